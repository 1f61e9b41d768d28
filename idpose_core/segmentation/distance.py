"""The object's centre and distance from the depth of its visible points (a mask's readings), for the
scale of its pose."""
from __future__ import annotations

import numpy as np

from idpose_core.segmentation.errors import DepthSegmentationError
from idpose_core.segmentation.plane import backproject
from idpose_core.view_input import ViewInput


def object_centre(view: ViewInput, mask: np.ndarray) -> np.ndarray:
    """The object's centre (3,) in the view's optical frame (m), from the depth of its visible points.

    The visible surface lies in front of the centre: for a ball of radius r seen from afar its mean depth
    is ``D - 2r/3`` while it spans ``2r`` across, so the centre is taken on the ray through the visible points'
    mean, a third of their extent across the view (5th to 95th percentile along its widest axis) beyond it.
    On the synthetic tabletop views its distance is 2 % off the true distance on average, 5 % at worst
    (``bench/tabletop.py``); a ball of 10 cm at 60 cm comes out 4 % short (the trimmed extent is less
    than the diameter). DepthSegmentationError without readings.
    """
    if view.depth is None or view.intrinsics is None:
        raise DepthSegmentationError("the object distance needs a depth image and the camera intrinsics")
    points, valid = backproject(view.depth, view.intrinsics)
    visible = points[valid & mask]
    if len(visible) < 10:
        raise DepthSegmentationError(f"only {len(visible)} depth readings on the object")
    centre = visible.mean(axis=0)
    ray = centre / np.linalg.norm(centre)
    across = visible - np.outer(visible @ ray, ray)
    basis = np.linalg.svd(across - across.mean(axis=0), full_matrices=False)[2][:2]
    spans = [np.subtract(*np.percentile(across @ axis, [95, 5])) for axis in basis]
    return ray * (np.linalg.norm(centre) + max(spans) / 3.0)


def object_distance(view: ViewInput, mask: np.ndarray) -> float:
    """Camera to object centre (m): the norm of ``object_centre``."""
    return float(np.linalg.norm(object_centre(view, mask)))
