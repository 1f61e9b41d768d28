"""The support plane: the depth back-projected to points, and the largest plane that faces up (RANSAC), with
tolerances that grow with each reading's depth."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from idpose_core.segmentation.errors import DepthSegmentationError

RANSAC_ITERATIONS = 300
RANSAC_SAMPLE = 4000  # points scored per plane hypothesis
PLANE_TOLERANCE = 0.01  # m, or 1 % of the reading's depth when larger: a point on the plane
MIN_PLANE_SHARE = 0.1  # of the valid points: a smaller plane is no support
UP_TOLERANCE_DEG = 30.0  # the plane normal vs gravity's up (when known)
IMAGE_UP_MIN = 0.3  # without gravity: the normal's component towards the top of the image at least this
STEEP_UP_MIN = 0.05  # ... or this, when no plane tilted as much holds enough points: a camera looking steeply down
# sees the table nearly face on (a wall faces a camera that looks down with a normal towards the image bottom)
STEEP_GAIN = 2.0  # ... or when such a flatter plane holds this many times the readings of the tilted one
BAND_OVERLAP = 0.5  # ... and this much of the tilted one's readings: it grazes the table in a band (not a wall)


@dataclass(frozen=True)
class Plane:
    """Points p with ``normal . p + offset = 0``; ``normal`` (3,) unit, pointing to the side the camera is on."""

    normal: np.ndarray
    offset: float

    def height(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (...,) of points (..., 3) from the plane, positive on the camera's side."""
        return points @ self.normal + self.offset


def backproject(depth: np.ndarray, intrinsics: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points (H, W, 3) in the optical frame and the valid-reading mask (H, W) of a depth image (metres)."""
    depth = np.asarray(depth, dtype=np.float64)
    valid = np.isfinite(depth) & (depth > 0)
    z = np.where(valid, depth, 0.0)
    rows, cols = np.indices(depth.shape, dtype=np.float64)
    k = np.asarray(intrinsics, dtype=np.float64)
    x = (cols - k[0, 2]) * z / k[0, 0]
    y = (rows - k[1, 2]) * z / k[1, 1]
    return np.stack([x, y, z], axis=-1), valid


def depth_tolerance(depth: np.ndarray, base: float, share: float) -> np.ndarray:
    """Per reading: ``base`` metres, or ``share`` of its depth when larger (depth noise grows with distance; a far
    wall in the view does not loosen the test on the table)."""
    return np.maximum(base, share * depth)


def support_plane(points: np.ndarray, up: np.ndarray | None, rng: np.random.Generator) -> Plane:
    """The largest plane among ``points`` (M, 3) that can carry an object: its normal within
    ``UP_TOLERANCE_DEG`` of ``up`` (optical frame) when given, else tilted towards the image top by
    ``IMAGE_UP_MIN`` (or only ``STEEP_UP_MIN`` when no such plane holds enough points, or when the flatter one
    holds ``STEEP_GAIN`` times as many, among them ``BAND_OVERLAP`` of the tilted one's: a camera looking steeply
    down, not a wall before a table). DepthSegmentationError when no plane holds ``MIN_PLANE_SHARE`` of the
    points."""
    if len(points) < 3:
        raise DepthSegmentationError("too few depth readings to find a support plane")
    scored = points[rng.choice(len(points), size=min(RANSAC_SAMPLE, len(points)), replace=False)]
    tolerance = depth_tolerance(scored[:, 2:], PLANE_TOLERANCE, 0.01)
    triples = points[rng.integers(0, len(points), size=(RANSAC_ITERATIONS, 3))]
    normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
    lengths = np.linalg.norm(normals, axis=1)
    usable = lengths > 1e-12
    normals = normals[usable] / lengths[usable, None]
    anchors = triples[usable, 0]
    normals *= np.where(np.sum(normals * anchors, axis=1) > 0, -1.0, 1.0)[:, None]  # towards the camera
    if up is not None:
        tiers = [normals @ np.asarray(up, dtype=np.float64) >= math.cos(math.radians(UP_TOLERANCE_DEG))]
    else:
        tiers = [-normals[:, 1] >= IMAGE_UP_MIN, -normals[:, 1] >= STEEP_UP_MIN]
    if not tiers[-1].any():
        raise DepthSegmentationError("no support plane facing up in the depth image")
    offsets = -np.sum(normals * anchors, axis=1)
    inliers = np.abs(scored @ normals.T + offsets) < tolerance  # (sample, hypotheses)
    counts = inliers.sum(axis=0)
    bests = [int(np.argmax(np.where(usable, counts, -1))) for usable in tiers]
    shares = [float(inliers[:, best].mean()) if usable.any() else 0.0 for best, usable in zip(bests, tiers)]
    chosen = next((tier for tier, share in enumerate(shares) if share >= MIN_PLANE_SHARE), None)
    if chosen is not None and shares[-1] >= STEEP_GAIN * shares[chosen]:
        tilted, flatter = inliers[:, bests[chosen]], inliers[:, bests[-1]]
        if (tilted & flatter).sum() >= BAND_OVERLAP * tilted.sum():
            chosen = len(tiers) - 1  # the table seen steeply: a tilted plane only grazed it in a band
    if chosen is None:
        raise DepthSegmentationError(f"no support plane in the depth image (the best holds {100 * shares[-1]:.0f} % "
                                     f"of the readings, {100 * MIN_PLANE_SHARE:.0f} % needed)")
    best = bests[chosen]
    on_plane = scored[inliers[:, best]]  # least squares on the inliers for a steadier plane
    centre = on_plane.mean(axis=0)
    normal = np.linalg.svd(on_plane - centre)[2][2]
    normal = normal if normal @ normals[best] > 0 else -normal
    return Plane(normal, float(-normal @ centre))
