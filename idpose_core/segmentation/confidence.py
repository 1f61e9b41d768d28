"""How separable the kept object is from what the cut left out: along the outline of the target's piece, the share
of readings that lie clearly apart from it (the table, the room well behind, an occluder well in front) rather
than attached to it in 3-D without being kept (a wall it almost touches, a box leaning on it, a part the cut
dropped)."""
from __future__ import annotations

import cv2
import numpy as np

from idpose_core.segmentation.pieces import nearest_index
from idpose_core.segmentation.plane import depth_tolerance

SEPARATION = 0.03  # m, or SEPARATION_SHARE of the depth when larger: a reading beside the object this far from its
# nearest kept point is apart from it
SEPARATION_SHARE = 0.05
MIN_MASK_CONFIDENCE = 0.9  # under this, more than a tenth of the readings along the outline are attached to what the
# cut left out: the cut says so, and it cannot vouch for the object it kept (no development view fell under it; see
# docs/robot_inputs.md#whole-objects)
OUTLINE_PX = (2, 4)  # px outside the piece: the band whose readings are judged (the first pixels out may be the
# object's own edge, which a depth jump's line or the stereo shadow beside it leaves out of the piece)


def outline_band(piece: np.ndarray) -> np.ndarray:
    """(H, W) bool: the band from ``OUTLINE_PX[0]`` to ``OUTLINE_PX[1]`` px outside ``piece`` (H, W) bool."""
    kernel = np.ones((3, 3), np.uint8)
    near, far = (cv2.dilate(piece.astype(np.uint8), kernel, iterations=px).astype(bool) for px in OUTLINE_PX)
    return far & ~near


def attached_outside(piece: np.ndarray, band: np.ndarray, points: np.ndarray, above: np.ndarray) -> np.ndarray:
    """(H, W) bool: the readings in ``band`` (``outline_band`` of ``piece``) that stand above the table (``above``
    (H, W)) within ``SEPARATION`` of the nearest reading of the piece (``points`` (H, W, 3)): what touches the object
    without being kept."""
    kept = piece & above
    if not kept.any():
        return np.zeros(piece.shape, bool)
    read = band & above
    nearest = nearest_index(kept).ravel()[read.ravel()]
    gap = np.linalg.norm(points[read] - points.reshape(-1, 3)[nearest], axis=-1)
    attached = np.zeros(piece.shape, bool)
    attached[read] = gap < depth_tolerance(points[read][:, 2], SEPARATION, SEPARATION_SHARE)
    return attached


def mask_confidence(piece: np.ndarray, points: np.ndarray, valid: np.ndarray, above: np.ndarray) -> float:
    """In [0, 1]: the share of the readings (``valid`` (H, W)) just outside ``piece`` (H, W) bool that lie apart from
    the object (``attached_outside``: not above the table within ``SEPARATION`` of it); 1 where no reading borders
    it."""
    band = outline_band(piece)
    read = band & valid
    if not read.any():
        return 1.0
    return float(1.0 - attached_outside(piece, band, points, above)[read].sum() / read.sum())
