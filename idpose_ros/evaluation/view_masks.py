"""What the offline pipeline made of each view of a bag: its masks saved as files, and scored against true masks;
each estimate's fused object cloud saved too.

``--save-views DIR`` writes, for every view an estimate used, ``DIR/views/<view id>_mask.png`` (the object
mask in the view's own image, mono8 0/255; a de-rolled view's mask mapped back to its pixels) and
``DIR/views/<view id>_crop.png`` (the preprocessed image the model saw; a view in several estimates keeps the
crop of the last one, which the protocol's order makes the largest view set of its last pick, since the shared
window depends on the set). When the bag carries true target masks (``GroundTruthOptions.true_mask_topic``),
each view's mask IoU is recorded. Both need the masks, which only the offline estimator gives. An estimate with an
object cloud (its anchor had depth) writes it as ``DIR/clouds/<sample>_<n>.ply`` (x, y, z in metres in the anchor's
optical frame, red, green, blue).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from plyfile import PlyData, PlyElement
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import Image

from idpose_core.depth_fusion import ObjectCloud
from idpose_core.evaluation.protocol import EstimateTask
from idpose_core.evaluation.run import EstimateOutcome
from idpose_core.preprocessing import mask_iou
from idpose_core.stamps import match_stamps
from idpose_ros.evaluation.bag_io import BagError, open_bag, topic_connections
from idpose_ros.evaluation.bag_views import BagViews
from msg_adapters import AdapterError, image_to_mask, stamp_nanoseconds

IMAGE_TYPE = "sensor_msgs/msg/Image"


def check_save_views(mode: str) -> None:
    """ValueError unless views can be saved in this estimator ``mode``: the node (replay) does not return masks."""
    if mode != "offline":
        raise ValueError(f"--save-views needs --mode offline: in {mode} mode the estimator node returns poses, not "
                         "the masks and crops it made")


def read_true_masks(bag: str | Path, topic: str, views: BagViews, view_ids: set[int], tolerance: float
                    ) -> dict[int, np.ndarray]:
    """The true mask (H, W) bool of each chosen view: the mono8 image on ``topic`` nearest its stamp within
    ``tolerance`` s (views without one are left out; a bag without the topic gives none)."""
    infos = [info for info in views.views if info.view_id in view_ids]
    with open_bag(bag) as reader:
        if topic not in reader.topics:
            return {}
        raw = [raw for _, _, raw in reader.messages(connections=topic_connections(reader, topic, (IMAGE_TYPE,)))]
    messages = [deserialize_message(item, Image) for item in raw]
    matches = match_stamps([info.stamp for info in infos], [stamp_nanoseconds(m.header.stamp) for m in messages],
                           int(round(tolerance * 1e9)))
    masks = {}
    for info, index in zip(infos, matches):
        if index >= 0:
            try:
                masks[info.view_id] = image_to_mask(messages[index])
            except AdapterError as err:
                raise BagError(f"{topic}: the true mask of view {info.view_id}: {err}") from None
    return masks


@dataclass
class ViewMasks:
    """Takes each estimate's outcome (``evaluate_tasks``'s ``on_estimate``): writes the views' masks and crops
    under ``out / "views"`` and its object cloud under ``out / "clouds"`` when ``out`` is set, and the mask IoU of
    every view with a true mask (``ious``)."""

    out: Path | None = None
    true_masks: dict[int, np.ndarray] = field(default_factory=dict)
    ious: dict[int, float] = field(default_factory=dict)

    def __call__(self, task: EstimateTask, outcome: EstimateOutcome) -> None:
        estimate = outcome.estimate
        if estimate is None or not estimate.masks:
            return
        folder = None if self.out is None else self.out / "views"
        if folder is not None:
            folder.mkdir(parents=True, exist_ok=True)
            if estimate.cloud is not None:
                (self.out / "clouds").mkdir(exist_ok=True)
                write_ply(self.out / "clouds" / f"{task.sample}_{task.n}.ply", estimate.cloud)
        for k, view_id in enumerate(task.views):
            mask = estimate.masks[k]
            if view_id in self.true_masks:
                truth = self.true_masks[view_id]
                if truth.shape != mask.shape:
                    raise BagError(f"the true mask of view {view_id} is {truth.shape[1]}x{truth.shape[0]} px, its "
                                   f"image {mask.shape[1]}x{mask.shape[0]}")
                self.ious[view_id] = mask_iou(mask, truth)
            if folder is not None:
                write_png(folder / f"{view_id}_mask.png", np.where(mask, 255, 0).astype(np.uint8))
                write_png(folder / f"{view_id}_crop.png", cv2.cvtColor(estimate.crops[k], cv2.COLOR_RGB2BGR))

    def summary(self, topic: str) -> dict[str, Any] | None:
        """The IoU figures for report.json (None without true masks): views scored, mean, worst, per view."""
        if not self.ious:
            return None
        values = list(self.ious.values())
        return {"true_mask_topic": topic, "views": len(values), "mean": float(np.mean(values)),
                "worst": float(np.min(values)), "per_view": dict(sorted(self.ious.items()))}


def write_ply(path: Path, cloud: ObjectCloud) -> None:
    """Write ``cloud`` as a binary PLY of vertices (x, y, z float32, red, green, blue uint8)."""
    vertices = np.empty(len(cloud.points), dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u1"),
                                                  ("green", "u1"), ("blue", "u1")])
    for k, axis in enumerate("xyz"):
        vertices[axis] = cloud.points[:, k]
    for k, channel in enumerate(("red", "green", "blue")):
        vertices[channel] = cloud.colours[:, k]
    PlyData([PlyElement.describe(vertices, "vertex")]).write(str(path))


def write_png(path: Path, image: np.ndarray) -> None:
    """Write ``image`` (mono8, or BGR) as a png; OSError naming the path when it cannot."""
    if not cv2.imwrite(str(path), image):
        raise OSError(f"could not write {path}")
