"""Surface normals of back-projected depth by finite differences: the concave creases between two objects
and the table's face under an object's base are told by them."""
from __future__ import annotations

import numpy as np

NORMAL_STEP = 2  # px either side for the surface normal's finite differences


def surface_normals(points: np.ndarray, same: np.ndarray, step: int = NORMAL_STEP) -> tuple[np.ndarray, np.ndarray]:
    """Unit surface normals (H, W, 3), facing the camera, from finite differences ``step`` px either side, and
    where they hold (H, W) bool: ``same`` (H, W) int labels readings that belong together (0: no reading), and a
    normal holds where its four neighbours carry the pixel's own non-zero label (no depth jump, no hole between)."""
    across = np.zeros_like(points)
    down = np.zeros_like(points)
    across[:, step:-step] = points[:, 2 * step:] - points[:, :-2 * step]
    down[step:-step] = points[2 * step:] - points[:-2 * step]
    normal = np.cross(across, down)
    length = np.linalg.norm(normal, axis=-1)
    centre = same[step:-step, step:-step]
    holds = np.zeros(same.shape, bool)
    holds[step:-step, step:-step] = ((centre > 0) & (same[2 * step:, step:-step] == centre)
                                     & (same[:-2 * step, step:-step] == centre)
                                     & (same[step:-step, 2 * step:] == centre)
                                     & (same[step:-step, :-2 * step] == centre))
    holds &= length > 0
    normal = normal / np.maximum(length, 1e-12)[..., None]
    normal *= np.where(np.sum(normal * points, axis=-1) > 0, -1.0, 1.0)[..., None]
    return normal, holds
