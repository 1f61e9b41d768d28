"""What a classical baseline returns for the n views of one estimate, and how such poses get a metric scale.

Structure from motion and two-view geometry give camera poses up to a scale. The views look at the
object (as Zero-1-to-3 assumes too), so the point nearest to every registered camera's optical axis is
the object centre; scaling the poses so that it sits at the anchor's known distance gives them metres,
as the anchor's distance gives ID-Pose's relative radii theirs.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CONVERGED, FEWER, FAILED = "all", "fewer", "failed"  # every view registered / some (a retry with fewer) / none
# Axes this close to parallel (smallest eigenvalue of the normal matrix, per axis) locate no point.
_MIN_AXIS_SPREAD = 1e-4


@dataclass(frozen=True)
class BaselineEstimate:
    """Poses of n views from a baseline: ``poses`` (n, 4, 4) optical camera poses in the anchor camera's frame
    (poses[0] = identity, metres), valid where ``registered`` (n,) is True (the anchor always is);
    ``status`` is ``CONVERGED``, ``FEWER`` or ``FAILED``; ``seconds`` the wall time."""

    poses: np.ndarray
    registered: np.ndarray
    status: str
    seconds: float

    @classmethod
    def failure(cls, n: int, seconds: float) -> BaselineEstimate:
        """No view but the anchor has a pose."""
        return cls(np.repeat(np.eye(4)[None], n, axis=0), np.arange(n) == 0, FAILED, seconds)


def status_of(registered: np.ndarray) -> str:
    """``CONVERGED`` when every view is registered, ``FAILED`` when only the anchor is, else ``FEWER``."""
    count = int(np.count_nonzero(registered))
    return CONVERGED if count == len(registered) else FAILED if count <= 1 else FEWER


def in_anchor_frame(cam_from_world: np.ndarray) -> np.ndarray:
    """Camera poses (n, 4, 4) in the first camera's frame, from world-to-camera transforms (n, 4, 4)."""
    cam_from_world = np.asarray(cam_from_world, dtype=np.float64)
    return cam_from_world[0] @ np.linalg.inv(cam_from_world)


def object_centre(poses: np.ndarray) -> np.ndarray | None:
    """The point (3,) nearest (least squares) to the optical axes (+z) of the camera poses (k, 4, 4), k >= 2,
    or None when the axes are near parallel."""
    centres, axes = poses[:, :3, 3], poses[:, :3, 2] / np.linalg.norm(poses[:, :3, 2], axis=-1, keepdims=True)
    projectors = np.eye(3) - axes[:, :, None] * axes[:, None, :]  # onto the plane normal to each axis
    normal, rhs = projectors.sum(axis=0), np.einsum("kij,kj->i", projectors, centres)
    if np.linalg.eigvalsh(normal)[0] < _MIN_AXIS_SPREAD * len(poses):
        return None
    return np.linalg.solve(normal, rhs)


def scale_to_object_distance(poses: np.ndarray, registered: np.ndarray, distance: float) -> np.ndarray | None:
    """The poses (n, 4, 4) in the anchor's frame with their translations scaled so that the object centre
    (``object_centre`` of the registered views) lies ``distance`` from the anchor; None when the axes locate
    no point in front of the anchor."""
    centre = object_centre(np.asarray(poses)[np.asarray(registered)])
    if centre is None or centre[2] <= 0.0:
        return None
    scaled = np.array(poses, dtype=np.float64)
    scaled[:, :3, 3] *= distance / float(np.linalg.norm(centre))
    return scaled
