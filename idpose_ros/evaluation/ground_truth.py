"""Where a bag's views and their true camera poses are, and reading them: the image topic, /tf or a PoseStamped
topic, the object's centre and the world's up axis, and the views' other inputs."""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from idpose_core.evaluation.protocol import OBJECT_CENTER, WORLD_UP
from idpose_ros.evaluation.bag_io import BagError
from idpose_ros.evaluation.bag_views import BagViews, ExtraTopics, default_camera_info_topic, read_bag_views

TRUE_MASK_TOPIC = "/ground_truth/target_mask"  # where make_synthetic_bag --scene tabletop puts the target's masks


@dataclass(frozen=True)
class GroundTruthOptions:
    """Where a bag's views and their true camera poses are: the image topic, and /tf from ``world_frame``
    (or the PoseStamped ``gt_topic`` matched within ``gt_tolerance`` s); the object's centre and the
    world's up axis in the world frame; the views' other inputs (depth, mask, intrinsics, gravity); and
    ``true_mask_topic``, the target's true masks (mono8, matched by stamp within ``extras.tolerance``) that
    the offline pipeline's masks are scored against when the bag has the topic (never an input)."""

    image_topic: str = "/camera/image_raw"
    world_frame: str = "world"
    gt_topic: str | None = None
    gt_tolerance: float = 0.01
    object_center: tuple[float, float, float] = OBJECT_CENTER
    up: tuple[float, float, float] = WORLD_UP
    extras: ExtraTopics = ExtraTopics()
    true_mask_topic: str = TRUE_MASK_TOPIC

    @property
    def inputs(self) -> ExtraTopics:
        """``extras`` with the CameraInfo topic beside the image topic unless one is named (optional either way)."""
        topic = self.extras.camera_info_topic or default_camera_info_topic(self.image_topic)
        return replace(self.extras, camera_info_topic=topic)

    @property
    def description(self) -> str:
        return (f"PoseStamped on {self.gt_topic} (within {self.gt_tolerance:g} s)" if self.gt_topic
                else f"/tf + /tf_static ({self.world_frame} -> image frame, at the image stamp)")


def read_views(bag: Path, ground_truth: GroundTruthOptions) -> BagViews:
    """The bag's views with their ground truth; BagError for an unreadable bag or a missing topic."""
    gt = ground_truth
    return read_bag_views(bag, gt.image_topic, gt.world_frame, gt.gt_topic, gt.gt_tolerance, gt.inputs)


def require_usable(views: BagViews, image_topic: str) -> None:
    """BagError when fewer than 2 views have an image and ground truth."""
    if len(views.pool) < 2:
        reasons = "; ".join(f"view {k}: {r}" for k, r in list(views.skipped.items())[:3])
        raise BagError(f"fewer than 2 usable views ({len(views.pool)} of {len(views.views)} on {image_topic})"
                       + (f"; skipped {reasons}" if reasons else ""))


def skipped_note(views: BagViews) -> str | None:
    """One line on the views that cannot be evaluated, or None."""
    if not views.skipped:
        return None
    view, reason = next(iter(views.skipped.items()))
    return (f"{len(views.skipped)} of {len(views.views)} views skipped (reasons in report.json), "
            f"e.g. view {view}: {reason}")
