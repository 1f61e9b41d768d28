"""The verifier: how well two views' depth agrees under a relative pose, in both directions.

Each view's points are placed in the other camera and projected into its depth image. A point that lands on the
other view's observed surface, inside the matching region, supports the pose; one that lands in front of every
surface observed around its pixel lies in space the other camera saw empty and counts against it (the
neighbourhood keeps a point on an outline, a pixel off the silhouette, from counting as free space); one behind it
is hidden and says nothing. Points on the surface whose colour matches the other view's pixel add colour support.
Two regions are checked: the object itself, and the object with its surroundings (the table patch and whatever
stands near it, ``CONTEXT_EXTENTS`` object sizes around its centre). The object alone cannot tell a wrong turn that
lays the two views' visible sides onto each other from the right pose; its surroundings can, as long as they stood
still.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

MAX_POINTS = 1500  # points each direction checks: a fixed sample keeps the cost per hypothesis flat
SURFACE_SHARE = 0.012  # of the depth: a point within this (or the caller's floor) of the surface lies on it
ANGLE_SLACK = 0.05  # rad: a point this far off per metre from the object's centre still counts on the surface
MASK_GROWTH_PX = 3  # px the object mask is grown by: its edge is eroded before points are taken
CONTEXT_EXTENTS = 2.0  # the surroundings checked: points within this many object extents of its centre
CHROMA_TOLERANCE = 0.06  # largest difference in chromaticity (r, g over r + g + b) for colours to agree
FREE_SPACE_WEIGHT = 4.0  # a point in seen-empty space costs this many supporting points
FREE_SPACE_WINDOW_PX = 2  # px around a pixel whose nearest reading a point must lie in front of to be in free space
COLOUR_WEIGHT = 0.5  # weight of the colour-agreeing share


@dataclass(frozen=True)
class Region:
    """One region of a view as the verifier checks it: its ``mask`` (H, W) bool, its ``points`` (M, 3) in the
    view's optical frame (at most ``MAX_POINTS``) and their ``chroma`` (M, 2)."""

    mask: np.ndarray
    points: np.ndarray
    chroma: np.ndarray


@dataclass(frozen=True)
class ViewEvidence:
    """What the verifier needs of one view: ``depth`` (H, W) m (0 = no reading), ``nearest`` (H, W) m: the
    nearest reading within ``FREE_SPACE_WINDOW_PX`` of each pixel (0 = none), ``intrinsics`` K (3, 3), the
    ``chroma`` (H, W, 2) of its colour image, the object's ``centre`` (3,) in its optical frame, and two regions:
    the ``object`` and its ``context``."""

    depth: np.ndarray
    nearest: np.ndarray
    intrinsics: np.ndarray
    chroma: np.ndarray
    centre: np.ndarray
    object: Region
    context: Region


@dataclass(frozen=True)
class Agreement:
    """Shares of the projected points that ``support`` the pose (on the surface, in the region), lie in
    ``free_space``, and support it with agreeing ``colour``."""

    support: float
    free_space: float
    colour: float

    @property
    def score(self) -> float:
        """Support less weighted free space plus weighted colour (higher is better; 1.5 at most)."""
        return self.support - FREE_SPACE_WEIGHT * self.free_space + COLOUR_WEIGHT * self.colour


@dataclass(frozen=True)
class Verdict:
    """Both regions' agreement under one pose, and their sum as the ``score``."""

    object: Agreement
    context: Agreement

    @property
    def score(self) -> float:
        return self.object.score + self.context.score


def chromaticity(rgb: np.ndarray) -> np.ndarray:
    """(..., 3) uint8 RGB -> (..., 2) float32 (r, g) / (r + g + b): colour without its brightness."""
    values = np.asarray(rgb, dtype=np.float32)
    return values[..., :2] / np.maximum(values.sum(axis=-1, keepdims=True), 1.0)


def nearest_reading(depth: np.ndarray, radius: int) -> np.ndarray:
    """(H, W) m: the smallest non-zero reading of ``depth`` (H, W) within ``radius`` px of each pixel (0 = none)."""
    readings = np.where(depth > 0, depth, np.inf).astype(np.float32)
    nearest = cv2.erode(readings, np.ones((2 * radius + 1,) * 2, np.uint8), borderType=cv2.BORDER_REPLICATE)
    return np.where(np.isfinite(nearest), nearest, 0.0)


def _region(mask: np.ndarray, points: np.ndarray, chroma: np.ndarray, rng: np.random.Generator) -> Region:
    inside = np.flatnonzero(mask.ravel())
    if len(inside) > MAX_POINTS:
        inside = rng.choice(inside, MAX_POINTS, replace=False)
    return Region(mask, points.reshape(-1, 3)[inside], chroma.reshape(-1, 2)[inside])


def view_evidence(points: np.ndarray, valid: np.ndarray, intrinsics: np.ndarray, rgb: np.ndarray, mask: np.ndarray,
                  centre: np.ndarray, extent: float, seed: int = 0) -> ViewEvidence:
    """A view's evidence from its depth back-projected (``backproject``: ``points`` (H, W, 3), ``valid`` (H, W)),
    intrinsics, colour image, object ``mask`` (H, W) bool, the object's ``centre`` (3,) and size ``extent`` (m)."""
    depth = np.where(valid, points[..., 2], 0.0)
    chroma = chromaticity(rgb)
    grown = cv2.dilate(np.asarray(mask, np.uint8), np.ones((2 * MASK_GROWTH_PX + 1,) * 2, np.uint8)).astype(bool)
    near = valid & (np.linalg.norm(points - centre, axis=-1) <= CONTEXT_EXTENTS * extent)
    rng = np.random.default_rng(seed)
    return ViewEvidence(depth, nearest_reading(depth, FREE_SPACE_WINDOW_PX), np.asarray(intrinsics, dtype=np.float64),
                        chroma, np.asarray(centre, np.float64), _region(grown & valid, points, chroma, rng),
                        _region(near | (grown & valid), points, chroma, rng))


def one_way(points: np.ndarray, chroma: np.ndarray, target: ViewEvidence, region: np.ndarray,
            target_from_source: np.ndarray, tolerance_floor: float) -> Agreement:
    """How source ``points`` (M, 3) with their ``chroma`` (M, 2), placed in the target camera by
    ``target_from_source`` (4, 4), agree with the ``target`` view's depth inside its ``region`` (H, W) bool;
    ``tolerance_floor`` (m): the least distance still counted on the surface."""
    placed = points @ target_from_source[:3, :3].T + target_from_source[:3, 3]
    k = target.intrinsics
    height, width = target.depth.shape
    z = placed[:, 2]
    ahead = z > 1e-6
    safe_z = np.where(ahead, z, 1.0)
    u = np.round(k[0, 0] * placed[:, 0] / safe_z + k[0, 2])
    v = np.round(k[1, 1] * placed[:, 1] / safe_z + k[1, 2])
    inside = ahead & (u >= 0) & (u < width) & (v >= 0) & (v < height)
    u, v = u[inside].astype(int), v[inside].astype(int)
    observed = target.depth[v, u]
    read = observed > 0
    if not read.any():
        return Agreement(0.0, 0.0, 0.0)
    u, v, observed = u[read], v[read], observed[read]
    z, chroma = z[inside][read], chroma[inside][read]
    reach = np.linalg.norm(placed[inside][read] - target.centre, axis=1)
    tolerance = np.maximum(np.maximum(SURFACE_SHARE * observed, tolerance_floor), ANGLE_SLACK * reach)
    supported = (np.abs(z - observed) <= tolerance) & region[v, u]
    free = z < target.nearest[v, u] - tolerance
    agreeing = supported & (np.abs(chroma - target.chroma[v, u]).max(axis=1) <= CHROMA_TOLERANCE)
    count = float(len(z))
    return Agreement(supported.sum() / count, free.sum() / count, agreeing.sum() / count)


def _both_ways(first: ViewEvidence, second: ViewEvidence, first_from_second: np.ndarray, region: str,
               tolerance_floor: float) -> Agreement:
    second_region, first_region = getattr(second, region), getattr(first, region)
    forward = one_way(second_region.points, second_region.chroma, first, first_region.mask, first_from_second,
                      tolerance_floor)
    backward = one_way(first_region.points, first_region.chroma, second, second_region.mask,
                       np.linalg.inv(first_from_second), tolerance_floor)
    return Agreement((forward.support + backward.support) / 2, (forward.free_space + backward.free_space) / 2,
                     (forward.colour + backward.colour) / 2)


def verify(first: ViewEvidence, second: ViewEvidence, first_from_second: np.ndarray,
           tolerance_floor: float) -> Verdict:
    """The verdict on ``first_from_second`` (4, 4: the second view's optical frame in the first's): each region's
    agreement, both directions averaged."""
    return Verdict(_both_ways(first, second, first_from_second, "object", tolerance_floor),
                   _both_ways(first, second, first_from_second, "context", tolerance_floor))
