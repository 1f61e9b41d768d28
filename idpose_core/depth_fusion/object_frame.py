"""The fused object's pose and box: its centre, with axes from gravity when known, else the anchor camera's."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from idpose_core.depth_fusion.clouds import ObjectCloud


@dataclass(frozen=True)
class ObjectFrame:
    """``pose`` (4, 4): the object's box centre and axes in the anchor's optical frame; ``size`` (3,): the box's
    sides along those axes (m, 2nd to 98th percentile of the points, so a stray reading does not stretch it);
    ``axes_source``: "gravity" (z up, x horizontal away from the anchor camera) or "anchor" (the anchor's axes)."""

    pose: np.ndarray
    size: np.ndarray
    axes_source: str


def gravity_axes(up: np.ndarray) -> np.ndarray:
    """Rotation (3, 3) whose columns are x (the anchor's optical axis made horizontal), y, z = ``up`` (3,), in the
    anchor's optical frame; a camera looking straight down takes its image-down axis for x."""
    z = np.asarray(up, dtype=np.float64) / np.linalg.norm(up)
    for forward in (np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])):
        x = forward - (forward @ z) * z
        if np.linalg.norm(x) > 1e-3:
            break
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def object_frame(cloud: ObjectCloud, gravity_up: np.ndarray | None) -> ObjectFrame:
    """The box around ``cloud`` (in the anchor's optical frame) along gravity's axes when ``gravity_up`` (3,, the
    anchor's) is given, else along the anchor camera's."""
    axes = np.eye(3) if gravity_up is None else gravity_axes(gravity_up)
    local = cloud.points @ axes
    low, high = np.percentile(local, [2, 98], axis=0)
    pose = np.eye(4)
    pose[:3, :3] = axes
    pose[:3, 3] = axes @ ((low + high) / 2.0)
    return ObjectFrame(pose=pose, size=high - low, axes_source="anchor" if gravity_up is None else "gravity")
