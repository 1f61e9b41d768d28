"""Classical pose baselines beside ID-Pose on the same views: COLMAP's incremental structure from motion and
a two-view SIFT + essential-matrix estimate per anchor-target pair. numpy, OpenCV and pycolmap; no ROS.

``run_baseline(name, views, camera_matrix, object_distance)`` is the one entry point: the views as the node
gets them (RGB and an optional alpha), intrinsics when known (else ``DEFAULT_FOV_DEG``).
"""
from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from idpose_core.baselines.colmap import estimate_colmap
from idpose_core.baselines.features import estimate_features
from idpose_core.baselines.result import CONVERGED, FAILED, FEWER, BaselineEstimate
from idpose_core.cameras import pinhole_camera_matrix
from idpose_core.preprocessing import ALPHA_THRESHOLD, on_white

Baseline = Callable[[Sequence[np.ndarray], np.ndarray, float], BaselineEstimate]
# name -> (images RGB uint8 anchor first, camera matrix (3, 3), anchor's object distance) -> estimate
BASELINES: dict[str, Baseline] = {"colmap": estimate_colmap, "features": estimate_features}
TITLES = {"colmap": "COLMAP", "features": "SIFT + essential matrix"}
DEFAULT_FOV_DEG = 60.0  # horizontal field of view assumed without intrinsics (the paper's renders')


def run_baseline(name: str, views: Sequence[tuple[np.ndarray, np.ndarray | None]], camera_matrix: np.ndarray | None,
                 object_distance: float) -> BaselineEstimate:
    """The baseline ``name`` on views (rgb (H, W, 3) uint8, alpha (H, W) uint8 or None), anchor first.

    Where an alpha channel marks a background, it turns white as for ID-Pose, so every method sees the
    same object. Raises ValueError for an unknown name.
    """
    if name not in BASELINES:
        raise ValueError(f"unknown baseline {name!r}: choose from {', '.join(BASELINES)}")
    images = [rgb if alpha is None else on_white(rgb, alpha > ALPHA_THRESHOLD) for rgb, alpha in views]
    height, width = images[0].shape[:2]
    matrix = pinhole_camera_matrix(width, height, DEFAULT_FOV_DEG) if camera_matrix is None else camera_matrix
    return BASELINES[name](images, np.asarray(matrix, dtype=np.float64), object_distance)


__all__ = ["BASELINES", "CONVERGED", "DEFAULT_FOV_DEG", "FAILED", "FEWER", "TITLES", "Baseline",
           "BaselineEstimate", "run_baseline"]
