"""The object on a table, cut out with an aligned depth image and no learnt weights.

Back-project the depth with the intrinsics, find the support plane by RANSAC (the largest plane whose
normal points up: along gravity when it is known, else towards the top of the image), keep what
stands above it, split that into connected pieces at depth jumps (an object in front of another is a
different piece) and at concave folds between two objects that each stand on the table (a box touching
the target where no depth jump parts them), give a piece that does not reach the plane back to the piece
it stands out in front of and touches (a duck's head in front of its body: a part, not an object), leave
out what runs out of the image upwards (a wall whose top the camera does not see; an object of any size
shows its top), take the target's piece (the one in the region of interest, else the one nearest the image
centre), give it back its base (the bottom centimetre, under the height test's threshold: over its
footprint, not facing up) and let GrabCut, seeded from it, settle the boundary the depth leaves ragged.
Tolerances grow with each reading's depth, not the image's: a far wall does not loosen them. Depth is in metres
in the camera's optical frame; 0 or NaN means no reading.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from idpose_core.grabcut import grabcut_object
from idpose_core.view_input import ViewInput

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
MIN_HEIGHT = 0.008  # m, or 1.5 % of the depth when larger: standing on the plane
DEPTH_JUMP = 0.03  # relative depth step between neighbours that separates two pieces
SLANT_TOLERANCE = 0.5  # of a depth step: one within this of the steps either side continues a slanted surface
MIN_PIECE_SHARE = 0.002  # of the image: smaller pieces are noise
CENTRE_MARGIN = 0.05  # of the image size: pieces this much farther from the centre than the nearest one compete
SUPPORT_HEIGHT = 0.05  # m, or 5 % of the depth when larger: a piece with enough points this close to the plane
# (``stands``) stands on it (a curved bottom starts a few cm up); one without is carried by another piece
FOOT_SHARE = 0.004  # of a piece's readings that must lie within SUPPORT_HEIGHT of the plane for it to stand on it
FOOT_PIXELS = 8  # ... and at least this many: a thin leg in sight is enough, a speck of noise is not
ATTACH_GAP = 0.08  # m, or ATTACH_GAP_SHARE of the depth when larger: a carried piece's edge points lie this close
# to the piece carrying it (median); a head on a 20 cm body comes within 5 cm, a ball before a box that stands apart
# 13 cm or more; farther away the objects a camera frames are larger (a 1 m ball's marker stands 11 cm off at 1.1 m)
ATTACH_GAP_SHARE = 0.12  # of the median depth of the edge points (ATTACH_GAP)
CARRIER_INSET = 0.003  # m: a neighbour carries a piece from beneath when most of its points along their shared
# edge lie this far inside the piece's footprint (a table's legs under its top; a box behind the top lies outside)
MIN_SHARED_EDGE = 0.05  # of a carried piece's outline: it touches what carries it along more than this (a table
# top that touches a crate behind it at one corner is not carried by the crate)
GAP_POINTS = 400  # of each side, for the gap between two sets of points
SCENERY_TOP_SHARE = 0.9  # of a piece's top height: its readings on the image border reach this high, it runs out of
# the image upwards (a wall, the room), not an object standing in view
ROOM_HEIGHT = 0.3  # m above the plane: a piece this low is an object even where the image cuts its top off
UP_BORDER_COSINE = 0.3  # a border is an upper one when the up direction's image direction points this much at it
GRABCUT_ITERATIONS = 4
GRABCUT_BAND = 0.04  # of the piece's bounding-box diagonal: how far outside its edge GrabCut may grow it
HOLE_REACH = 4  # GrabCut's band reaches this many times as far through pixels without a depth reading
CORE_MARGIN = 2  # px inside the piece's edge that GrabCut may take away (thin legs stay)
BASE_MARGIN = 0.002  # m, or 0.4 % of the depth when larger: how far outside the piece's footprint on the plane a
# reading may lie and still be the piece's base (the band under ``MIN_HEIGHT`` that the height test leaves out)
FOOTPRINT_CELL = 0.001  # m: the grid the footprint is drawn on
BASE_SLICE = 0.02  # m above the height threshold: the piece's points that draw its footprint (higher up, an
# overhang such as a duck's head covers table that shows beneath it)
TABLE_TILT_DEG = 35.0  # a reading whose surface tilts less than this from the plane's normal faces up: the table
# (under a rounded bottom, inside the footprint), not the object's side or underside
NORMAL_STEP = 2  # px either side for the surface normal's finite differences
CREASE_STEP = 4  # px either side of a reading: the two surface points a concave crease is judged between
CREASE_NORMAL_STEP = 2  # px either side for their normals' finite differences
CREASE_SMOOTHING = 0.01  # m: the points are smoothed over neighbours this close in 3-D before the normals are taken
CREASE_ANGLE_DEG = 35.0  # the two normals differ by more than this at a crease
NECK_RADIUS = 3  # px: a piece narrower than a disc this wide is cut there too (then joined again unless the
# two sides are two objects, as at a concave fold)
OBJECT_CHROMA_DELTA = 0.04  # between the median chromaticities (r, g, b) / (r + g + b) of two parts that stay apart
# at a cut: two objects differ in colour, two faces of one object under a lamp only in brightness
FOOT_BAND = 0.01  # m above the height test's threshold: each of two parts kept apart at a crease reaches this low
# (a box's foot, a table's leg; not a marker low on a brick's side, which SUPPORT_HEIGHT would count as standing)


class DepthSegmentationError(ValueError):
    """Depth cannot cut the object out here (no intrinsics, too few readings, no plane, nothing above it)."""


@dataclass(frozen=True)
class Plane:
    """Points p with ``normal . p + offset = 0``; ``normal`` (3,) unit, pointing to the side the camera is on."""

    normal: np.ndarray
    offset: float

    def height(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (...,) of points (..., 3) from the plane, positive on the camera's side."""
        return points @ self.normal + self.offset


@dataclass(frozen=True)
class DepthCut:
    """``mask`` (H, W) bool of the target; ``depth_mask`` before GrabCut; the support ``plane``; ``note``: what the
    mask is unsure of (the central piece left out as the room), else empty."""

    mask: np.ndarray
    depth_mask: np.ndarray
    plane: Plane
    note: str = ""


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


def _tolerance(depth: np.ndarray, base: float, share: float) -> np.ndarray:
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
    tolerance = _tolerance(scored[:, 2:], PLANE_TOLERANCE, 0.01)
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


def _pieces(above: np.ndarray, depth: np.ndarray, valid: np.ndarray, nearest: np.ndarray) -> tuple[int, np.ndarray]:
    """Connected pieces of ``above`` that no depth jump crosses: (count, labels). Holes in the depth (no reading)
    that ``above`` pixels close around count as part of the piece, each with its nearest reading's depth (``nearest``:
    ``_nearest_index(valid)``): a stereo camera's shadow between an object and the wall behind it keeps the jump
    between them instead of bridging it."""
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
    closed = cv2.morphologyEx(above.astype(np.uint8), cv2.MORPH_CLOSE, kernel).astype(bool)
    holes = closed & ~valid
    above = above | holes
    depth = np.where(holes, depth.ravel()[nearest], depth)
    valid = valid | holes
    jump = np.zeros_like(above)
    inverse = np.where(valid, 1.0 / np.where(valid, depth, 1.0), np.nan)
    for axis in (0, 1):
        first = (slice(None, -1), slice(None)) if axis == 0 else (slice(None), slice(None, -1))
        second = (slice(1, None), slice(None)) if axis == 0 else (slice(None), slice(1, None))
        both = valid[first] & valid[second]
        nearer = np.minimum(depth[first], depth[second])
        steep = both & (np.abs(depth[first] - depth[second]) > DEPTH_JUMP * nearer)
        jump[first] |= steep & ~_slanted(inverse, axis)
    count, labels = cv2.connectedComponents((above & ~jump).astype(np.uint8), connectivity=4)
    return count, labels


def _slanted(inverse: np.ndarray, axis: int) -> np.ndarray:
    """(H - 1, W) for ``axis`` 0, (H, W - 1) for 1: whether the step between each pixel and the next along
    ``axis`` continues the steps on either side of it (``inverse`` depth (H, W), 1/m, NaN without a reading, is
    linear across the image on a plane and changes by the same amount within ``SLANT_TOLERANCE``): a surface seen
    at a grazing angle (a toy table's top seen from level with it), not the edge of one surface in front of
    another."""
    step = np.diff(inverse, axis=axis)
    pad = [(0, 0), (0, 0)]
    pad[axis] = (1, 1)
    padded = np.pad(step, pad, constant_values=np.nan)
    before = padded[(slice(None, -2), slice(None)) if axis == 0 else (slice(None), slice(None, -2))]
    after = padded[(slice(2, None), slice(None)) if axis == 0 else (slice(None), slice(2, None))]
    limit = SLANT_TOLERANCE * np.abs(step)
    with np.errstate(invalid="ignore"):
        return (np.abs(step - before) <= limit) & (np.abs(step - after) <= limit)


def _gap(front: np.ndarray, back: np.ndarray) -> float:
    """Median distance (m) from the points ``front`` (N, 3) to their nearest among ``back`` (M, 3), on at
    most ``GAP_POINTS`` of each (evenly spaced)."""
    front = front[np.linspace(0, len(front) - 1, min(len(front), GAP_POINTS)).astype(int)]
    back = back[np.linspace(0, len(back) - 1, min(len(back), GAP_POINTS)).astype(int)]
    return float(np.median(np.min(np.linalg.norm(front[:, None] - back[None], axis=-1), axis=1)))


def _attach_gap(edge: np.ndarray) -> float:
    """The most a piece's ``edge`` points (N, 3) may lie from a piece they are attached to (m): ``ATTACH_GAP``, or
    its share of their median depth when larger."""
    return float(_tolerance(np.median(edge[:, 2]), ATTACH_GAP, ATTACH_GAP_SHARE))


def _carriers_beneath(piece: int, inside: np.ndarray, ring: np.ndarray, labels: np.ndarray, height: np.ndarray,
                      points: np.ndarray, valid: np.ndarray, plane: Plane) -> list[int]:
    """The neighbours that carry ``piece`` (its pixels ``inside``, the band around it ``ring``) from beneath: along
    their shared edge they are lower than the piece, attached to it (within ``ATTACH_GAP``) and mostly over its
    footprint shrunk by ``CARRIER_INSET`` (a table's legs under its top)."""
    kernel = np.ones((3, 3), np.uint8)
    own = inside & valid
    if own.sum() < 3:
        return []
    carriers = []
    for other in np.unique(labels[ring]):
        if other in (0, piece):
            continue
        meeting = ring & (labels == other) & valid
        edge = cv2.dilate((labels == other).astype(np.uint8), kernel, iterations=2).astype(bool) & own
        if not meeting.any() or not edge.any() or np.median(height[meeting]) >= np.median(height[edge]):
            continue
        if (_gap(points[edge], points[meeting]) < _attach_gap(points[edge])
                and over_footprint(points[own], points[meeting], plane, -CARRIER_INSET).mean() > 0.5):
            carriers.append(int(other))
    return carriers


def stands(height: np.ndarray, support: np.ndarray) -> bool:
    """Whether a piece with these heights above the plane (N,) reaches it: at least ``FOOT_SHARE`` of its readings,
    and ``FOOT_PIXELS``, lie within ``support`` (N,) of it (a toy table's top with a leg in sight stands; a duck's
    head does not)."""
    low = int(np.count_nonzero(height <= support))
    return low >= max(FOOT_PIXELS, FOOT_SHARE * len(height))


def merge_carried_pieces(labels: np.ndarray, count: int, height: np.ndarray, points: np.ndarray,
                         valid: np.ndarray, support: np.ndarray, plane: Plane,
                         apart: frozenset[tuple[int, int]] = frozenset()) -> np.ndarray:
    """The labels with every piece joined by the smaller ones that carry it from beneath (``_carriers_beneath``: a
    table top and its legs), then every piece that still does not reach the plane (``stands``: too few of its
    points within ``support`` (H, W), m) joined to a neighbouring piece, larger or (standing on the plane) at
    least half as large, that it stands out in front of and is attached to (where they meet it is nearer the
    camera, its edge points lie within ``ATTACH_GAP`` of the neighbour's, and they share more than
    ``MIN_SHARED_EDGE`` of its outline; of several, the one with the longest shared edge): a part of an
    object that a depth jump cut off (a duck's head and back, larger than the breast below them). A piece behind
    its neighbour stays apart (an object partly hidden by the target), and so does one that is well in front of
    it (a ball whose lowest visible points are high on its curve, before a box behind it). Pieces that ``apart``
    pairs (``split_touching``: two objects) never join, nor do the pieces they have joined."""
    depth = np.where(valid, points[..., 2], 0.0)
    labels = labels.copy()
    owner = np.arange(count)  # the piece each original piece has joined

    def may_join(piece: int, other: int) -> bool:
        return not any({owner[first], owner[second]} == {piece, other} for first, second in apart)

    kernel = np.ones((3, 3), np.uint8)
    areas = np.bincount(labels.ravel(), minlength=count)
    standing = np.zeros(count, bool)
    for piece in np.flatnonzero(areas):
        inside = labels == piece
        standing[piece] = stands(height[inside], support[inside])
    for piece in np.argsort(areas)[::-1]:  # what stands beneath a piece, smaller than it, joins it (its legs)
        if piece == 0 or areas[piece] == 0:
            continue
        inside = labels == piece
        ring = cv2.dilate(inside.astype(np.uint8), kernel, iterations=2).astype(bool) & ~inside
        for other in _carriers_beneath(piece, inside, ring, labels, height, points, valid, plane):
            if areas[other] < areas[piece] and may_join(piece, other):
                labels[labels == other] = piece
                owner[owner == other] = piece
                areas[piece] += areas[other]
                areas[other] = 0
                standing[piece] |= standing[other]
    for piece in np.argsort(areas):  # smallest first: a head joins its body before the body is judged
        if piece == 0 or areas[piece] == 0 or standing[piece]:
            continue
        inside = labels == piece
        ring = cv2.dilate(inside.astype(np.uint8), kernel, iterations=2).astype(bool) & ~inside
        neighbours, shared = np.unique(labels[ring], return_counts=True)
        best, best_shared = 0, 0
        for other, length in zip(neighbours, shared):
            if other == 0 or other == piece or not may_join(piece, other) or not (
                    areas[other] > areas[piece] or (standing[other] and 2 * areas[other] >= areas[piece])):
                continue
            edge = cv2.dilate((labels == other).astype(np.uint8), kernel, iterations=2).astype(bool) & inside & valid
            behind = ring & (labels == other) & valid
            if length <= max(best_shared, MIN_SHARED_EDGE * ring.sum()) or not edge.any() or not behind.any():
                continue
            if (np.median(depth[edge]) < np.median(depth[behind])
                    and _gap(points[edge], points[behind]) < _attach_gap(points[edge])):
                best, best_shared = other, length
        if best:
            labels[inside] = best
            owner[owner == piece] = best
            areas[best] += areas[piece]
            areas[piece] = 0
    return labels


def _plane_basis(plane: Plane) -> np.ndarray:
    """(2, 3): two unit vectors spanning the plane, orthogonal to each other and to its normal."""
    seed = np.eye(3)[int(np.argmin(np.abs(plane.normal)))]
    first = np.cross(plane.normal, seed)
    first /= np.linalg.norm(first)
    return np.stack([first, np.cross(plane.normal, first)])


def surface_normals(points: np.ndarray, same: np.ndarray, step: int = NORMAL_STEP) -> tuple[np.ndarray, np.ndarray]:
    """Unit surface normals (H, W, 3), facing the camera, from finite differences ``step`` px either side, and
    where they hold (H, W) bool: ``same`` (H, W) int labels readings that belong together (0: no reading), and a
    normal holds where its four neighbours carry the pixel's own non-zero label (no depth jump, no hole between)."""
    step = NORMAL_STEP
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


def faces_up(points: np.ndarray, valid: np.ndarray, plane: Plane) -> np.ndarray:
    """(H, W) bool: the surface at each reading tilts less than ``TABLE_TILT_DEG`` from the plane's normal
    (``surface_normals``; False where a neighbour has no reading)."""
    normal, holds = surface_normals(points, valid.astype(np.int32))
    return holds & (np.abs(normal @ plane.normal) > math.cos(math.radians(TABLE_TILT_DEG)))


def concave_creases(points: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """(H, W) bool: readings on a concave fold of a piece's surface, where two faces meet in a valley seen from the
    camera (a box's face rising from a table top that touches it), not a ridge (a box's own edge). Between the
    readings ``CREASE_STEP`` px either side, in four directions: the normals differ by more than ``CREASE_ANGLE_DEG``
    and ``(n1 - n2) . (p1 - p2) < 0`` (the local convexity test of LCCP, Stein et al. 2014). The normals span
    ``CREASE_NORMAL_STEP`` px either side, on the points smoothed by a bilateral filter that averages only neighbours
    within ``CREASE_SMOOTHING`` metres in 3-D: a camera's depth noise tilts raw normals by tens of degrees."""
    smooth = cv2.bilateralFilter(points.astype(np.float32), 5, CREASE_SMOOTHING, 2).astype(np.float64)
    normal, holds = surface_normals(smooth, labels, CREASE_NORMAL_STEP)
    crease = np.zeros(labels.shape, bool)
    k = CREASE_STEP
    height, width = labels.shape
    limit = math.cos(math.radians(CREASE_ANGLE_DEG))
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        rows = slice(k * dy, height - k * dy) if dy else slice(None)
        centre_cols = slice(k, width - k) if dx else slice(None)
        first = (slice(0, height - 2 * k * dy) if dy else slice(None),
                 slice(0, width - 2 * k) if dx == 1 else slice(2 * k, None) if dx == -1 else slice(None))
        second = (slice(2 * k * dy, None) if dy else slice(None),
                  slice(2 * k, None) if dx == 1 else slice(0, width - 2 * k) if dx == -1 else slice(None))
        both = (holds[first] & holds[second] & (labels[first] == labels[second])
                & (labels[rows, centre_cols] == labels[first]))
        n1, n2 = normal[first], normal[second]
        folded = np.sum(n1 * n2, axis=-1) < limit
        valley = np.sum((n1 - n2) * (smooth[first] - smooth[second]), axis=-1) < 0
        crease[rows, centre_cols] |= both & folded & valley
    return crease


def _opened(labels: np.ndarray) -> np.ndarray:
    """(H, W) bool: each piece after a morphological opening by a disc of ``NECK_RADIUS`` px: what is left without
    its thin necks and limbs (where a box meets a table top's corner; a table's legs)."""
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * NECK_RADIUS + 1,) * 2)
    opened = np.zeros(labels.shape, bool)
    for piece in np.unique(labels[labels > 0]):
        opened |= cv2.morphologyEx((labels == piece).astype(np.uint8), cv2.MORPH_OPEN, disc).astype(bool)
    return opened


def _nearest_index(known: np.ndarray) -> np.ndarray:
    """(H, W) int: the flat index of the nearest ``known`` (H, W) bool pixel to each pixel (itself where known)."""
    _, nearest = cv2.distanceTransformWithLabels((~known).astype(np.uint8), cv2.DIST_L2, 5,
                                                 labelType=cv2.DIST_LABEL_PIXEL)
    lookup = np.zeros(int(nearest.max()) + 1, np.int64)
    lookup[nearest[known]] = np.flatnonzero(known)
    return lookup[nearest]


def _nearest_fill(seeds: np.ndarray, region: np.ndarray) -> np.ndarray:
    """``seeds`` (H, W) int (0: unlabelled) with every pixel of ``region`` (H, W) bool given the label of the nearest
    seed."""
    return np.where(region, seeds.ravel()[_nearest_index(seeds != 0)], seeds)


def _grown(seeds: np.ndarray, region: np.ndarray) -> np.ndarray:
    """``seeds`` (H, W) int (0: unlabelled) grown through ``region`` (H, W) bool a pixel at a time: each pixel of the
    region gets the label that reaches it first along the region (a table's thin leg goes to the top it hangs
    from, not to a box that stands nearer its foot). What no seed reaches stays 0."""
    grown = seeds.astype(np.uint16)
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    while True:
        reaching = cv2.dilate(grown, cross)
        reached = region & (grown == 0) & (reaching > 0)
        if not reached.any():
            return grown.astype(seeds.dtype)
        grown[reached] = reaching[reached]


def split_touching(labels: np.ndarray, count: int, points: np.ndarray, height: np.ndarray, footing: np.ndarray,
                   rgb: np.ndarray) -> tuple[int, np.ndarray, frozenset[tuple[int, int]]]:
    """(count, labels, the pairs of labels cut apart) with pieces cut apart where two objects touch without a depth
    jump. A piece is cut along its concave creases (``concave_creases``) and its thin necks (``_opened``) into parts
    (smaller ones, and the cut, go to the nearest large part); two neighbouring parts stay apart only when each
    stands on the plane by itself (``stands``: its ``height`` (H, W) under ``footing`` (H, W)) and their median
    chromaticities differ by more than ``OBJECT_CHROMA_DELTA``: two objects side by side (a box against a toy
    table's top). Otherwise they join again: a duck's head and body (one stands), a marker on a ball, a table's
    legs and top (too thin to be a large part). A piece that runs out of the image is left whole: what lies beyond
    cannot be judged (a wall behind the table, its tiles in different colours)."""
    crease = cv2.dilate(concave_creases(points, labels).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    crease |= (labels > 0) & ~_opened(labels)  # a cut with no gaps, and the thin necks where two objects meet
    cut_pairs: set[tuple[int, int]] = set()
    if not crease.any():
        return count, labels, frozenset(cut_pairs)
    chroma = rgb.astype(np.float64) + 1.0
    chroma /= chroma.sum(axis=-1, keepdims=True)
    labels = labels.copy()
    reach = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (4 * CREASE_STEP + 1,) * 2)
    for piece in np.setdiff1d(np.unique(labels[crease & (labels > 0)]), border_labels(labels)):
        inside = labels == piece
        parts_count, parts = cv2.connectedComponents((inside & ~crease).astype(np.uint8), connectivity=4)
        areas = np.bincount(parts.ravel(), minlength=parts_count)
        large = [part for part in range(1, parts_count) if areas[part] >= MIN_PIECE_SHARE * labels.size]
        if len(large) < 2:
            continue
        parts = _nearest_fill(_grown(np.where(np.isin(parts, large), parts, 0), inside), inside)
        alone = {part: stands(height[parts == part], footing[parts == part]) for part in large}
        colour = {part: np.median(chroma[parts == part], axis=0) for part in large}
        group = {part: part for part in large}
        for part in large:
            near = cv2.dilate((parts == part).astype(np.uint8), reach).astype(bool) & inside
            for other in np.unique(parts[near]):
                apart = (alone[part] and alone[other]
                         and np.linalg.norm(colour[part] - colour[other]) > OBJECT_CHROMA_DELTA)
                if other > part and not apart:
                    _union(group, part, int(other))
        roots = sorted({_root(group, part) for part in large}, key=lambda root: -areas[root])
        new = [int(piece)] + [count + index for index in range(len(roots) - 1)]
        for label, root in zip(new[1:], roots[1:]):
            labels[inside & np.isin(parts, [part for part in large if _root(group, part) == root])] = label
        cut_pairs |= {(first, second) for index, first in enumerate(new) for second in new[index + 1:]}
        count += len(roots) - 1
    return count, labels, frozenset(cut_pairs)


def _root(group: dict[int, int], part: int) -> int:
    """The representative of ``part``'s group (union-find)."""
    while group[part] != part:
        part = group[part]
    return part


def _union(group: dict[int, int], first: int, second: int) -> None:
    """Join the groups of ``first`` and ``second``."""
    group[_root(group, second)] = _root(group, first)


def over_footprint(object_points: np.ndarray, points: np.ndarray, plane: Plane, margin: float) -> np.ndarray:
    """(M,) bool: which of ``points`` (M, 3) lie over the footprint of ``object_points`` (N >= 3, 3), the convex hull
    of their projections onto the plane, grown by ``margin`` metres (shrunk when negative)."""
    basis = _plane_basis(plane)
    hull, query = object_points @ basis.T, points @ basis.T
    reach = max(margin, 0.0) + FOOTPRINT_CELL
    origin = hull.min(axis=0) - reach
    shape = np.ceil((hull.max(axis=0) + reach - origin) / FOOTPRINT_CELL).astype(int) + 1
    footprint = np.zeros((shape[1], shape[0]), np.uint8)
    cv2.fillConvexPoly(footprint, cv2.convexHull(np.round((hull - origin) / FOOTPRINT_CELL).astype(np.int32)), 1)
    grow = int(round(abs(margin) / FOOTPRINT_CELL))
    if grow:
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * grow + 1, 2 * grow + 1))
        footprint = cv2.dilate(footprint, disc) if margin > 0 else cv2.erode(footprint, disc)
    where = np.round((query - origin) / FOOTPRINT_CELL).astype(int)
    within = (where >= 0).all(axis=1) & (where[:, 0] < shape[0]) & (where[:, 1] < shape[1])
    over = np.zeros(len(query), bool)
    over[within] = footprint[where[within, 1], where[within, 0]] > 0
    return over


def recover_base(piece: np.ndarray, points: np.ndarray, valid: np.ndarray, height: np.ndarray, plane: Plane,
                 band: np.ndarray) -> np.ndarray:
    """The piece (H, W) bool with its base: the readings under the height test's threshold (``band`` (H, W), m)
    whose surface does not face up (``faces_up``: the table) and that lie over the piece's footprint on the plane
    (the convex hull, seen from above, of its points up to ``BASE_SLICE`` higher, grown by ``BASE_MARGIN``) and
    connect to it in the image: the bottom centimetre of the object, which the height test cannot tell from the
    table."""
    footing = points[piece & valid & (height <= band + BASE_SLICE)]
    if len(footing) < 3:
        return piece
    low = valid & ~piece & (height <= band) & (height > -band) & ~faces_up(points, valid, plane)
    margin = float(np.max(_tolerance(points[..., 2][piece & valid], BASE_MARGIN, 0.004)))
    rows, cols = np.nonzero(low)
    over = over_footprint(footing, points[rows, cols], plane, margin)
    base = np.zeros_like(piece)
    base[rows[over], cols[over]] = True
    count, labels = cv2.connectedComponents((piece | base).astype(np.uint8), connectivity=4)
    kept = np.unique(labels[piece])
    return np.isin(labels, kept[kept > 0])


def upper_border(shape: tuple[int, int], plane: Plane) -> np.ndarray:
    """The image's border (H, W) bool on the side(s) the plane's up direction points to in the image (the top rows
    for an upright camera): where a piece that rises out of the image leaves it."""
    up_x, up_y = plane.normal[0], plane.normal[1]  # up's image direction: the normal's x (right) and y (down)
    length = math.hypot(up_x, up_y) or 1.0
    border = np.zeros(shape, bool)
    border[0] |= -up_y / length > UP_BORDER_COSINE
    border[-1] |= up_y / length > UP_BORDER_COSINE
    border[:, 0] |= -up_x / length > UP_BORDER_COSINE
    border[:, -1] |= up_x / length > UP_BORDER_COSINE
    return border


def drop_scenery(labels: np.ndarray, count: int, height: np.ndarray, plane: Plane) -> np.ndarray:
    """The labels without the room: the pieces higher than ``ROOM_HEIGHT`` that rise out of the image, their
    highest readings on its upper border (``upper_border``; the 95th-percentile height of the piece's readings there
    at least ``SCENERY_TOP_SHARE`` of the piece's own): a wall whose top the camera does not see. An object in view,
    from a few centimetres to a metre or more, shows its top inside the image; one under ``ROOM_HEIGHT`` cut off at
    the image's edge is never taken for the room."""
    areas = np.bincount(labels.ravel(), minlength=count)
    upper = upper_border(labels.shape, plane)
    room = np.zeros(count, bool)
    for piece in np.flatnonzero(areas >= MIN_PIECE_SHARE * labels.size):  # smaller ones are never the target
        inside = labels == piece
        leaving = inside & upper
        if piece == 0 or not leaving.any():
            continue
        top = np.percentile(height[inside], 95)
        room[piece] = top > ROOM_HEIGHT and np.percentile(height[leaving], 95) >= SCENERY_TOP_SHARE * top
    return np.where(room[labels], 0, labels)


def border_labels(labels: np.ndarray) -> np.ndarray:
    """The labels (sorted, unique) found on the image border: pieces that run out of the image."""
    return np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))


def target_piece(labels: np.ndarray, count: int, roi: tuple[int, int, int, int] | None) -> np.ndarray:
    """The target's piece (H, W) bool: the one with most pixels inside ``roi`` among those it holds at least half
    of (a larger object nearer the camera may reach into a detector's loose box), or among all; else, among the
    pieces that do not touch the image border (if any), the largest of those whose centroid is within
    ``CENTRE_MARGIN`` of the one nearest the image centre (a part standing on the target, split from it at a
    depth jump, is near the centre too, and smaller). Pieces under ``MIN_PIECE_SHARE`` of the image are ignored;
    DepthSegmentationError when none is left."""
    height, width = labels.shape
    areas = np.bincount(labels.ravel(), minlength=count)
    areas[0] = 0
    candidates = np.flatnonzero(areas >= MIN_PIECE_SHARE * height * width)
    if len(candidates) == 0:
        raise DepthSegmentationError("nothing stands on the support plane")
    if roi is not None:
        x, y, w, h = roi
        window = labels[max(y, 0):y + h, max(x, 0):x + w]
        inside = np.bincount(window.ravel(), minlength=count)[candidates]
        held = inside * (2 * inside >= areas[candidates])  # pieces the box holds at least half of
        if inside.max() > 0:
            return labels == candidates[int(np.argmax(held if held.max() > 0 else inside))]
    inner = candidates[~np.isin(candidates, border_labels(labels))]
    candidates = inner if len(inner) else candidates
    rows, cols = np.indices(labels.shape)
    sums_r = np.bincount(labels.ravel(), weights=rows.ravel(), minlength=count)
    sums_c = np.bincount(labels.ravel(), weights=cols.ravel(), minlength=count)
    centres = np.stack([sums_r[candidates], sums_c[candidates]], axis=1) / areas[candidates, None]
    offsets = np.linalg.norm((centres - [(height - 1) / 2, (width - 1) / 2]) / [height, width], axis=1)
    central = candidates[offsets <= offsets.min() + CENTRE_MARGIN]
    return labels == central[int(np.argmax(areas[central]))]


def nearer_the_centre(dropped: np.ndarray, piece: np.ndarray) -> bool:
    """Whether a dropped piece (``dropped`` (H, W): labels, 0 elsewhere) of at least ``MIN_PIECE_SHARE`` of the
    image has its centroid nearer the image centre than ``piece`` (H, W) bool has."""
    centre = (np.array(piece.shape) - 1) / 2.0

    def offset(mask: np.ndarray) -> float:
        return float(np.linalg.norm(np.argwhere(mask).mean(axis=0) - centre))
    chosen = offset(piece)
    return any(offset(dropped == label) < chosen for label in np.unique(dropped[dropped > 0])
               if (dropped == label).sum() >= MIN_PIECE_SHARE * dropped.size)


def _fill_holes(mask: np.ndarray) -> np.ndarray:
    """The mask with every hole closed (what the outer contours enclose)."""
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    filled = np.zeros(mask.shape, np.uint8)
    cv2.drawContours(filled, contours, -1, 1, thickness=cv2.FILLED)
    return filled.astype(bool)


def grabcut_refine(rgb: np.ndarray, seed: np.ndarray, background: np.ndarray, unread: np.ndarray) -> np.ndarray:
    """GrabCut on a window around ``seed`` (H, W) bool: the seed but its outermost pixels is object, and so are its
    parts too thin to have an inside (a toy table's legs, its top seen edge on, whatever their colour);
    ``background`` and what lies beyond a band around the seed are background, the rest is left to the
    colours. The band reaches ``HOLE_REACH`` times as far into ``unread`` pixels (no depth reading) that touch the
    seed: a stereo camera reads nothing on a surface seen at a grazing angle (a box's top from low down), which
    only the colours can give back. Seeds OpenCV's RNG."""
    seed_u8 = seed.astype(np.uint8)
    x, y, w, h = cv2.boundingRect(seed_u8)
    band = max(2, int(round(GRABCUT_BAND * math.hypot(w, h))))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * band + 1, 2 * band + 1))
    edge = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * CORE_MARGIN + 1, 2 * CORE_MARGIN + 1))
    core = cv2.erode(seed_u8, edge).astype(bool)
    core |= seed & ~cv2.morphologyEx(seed_u8, cv2.MORPH_OPEN, edge).astype(bool)
    reach = cv2.dilate(seed_u8, kernel).astype(bool)
    far = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * HOLE_REACH * band + 1,) * 2)
    holes = (unread | seed) & cv2.dilate(seed_u8, far).astype(bool)
    parts = cv2.connectedComponents(holes.astype(np.uint8), connectivity=4)[1]
    reach |= np.isin(parts, np.unique(parts[seed]))
    labels = np.full(seed.shape, cv2.GC_BGD, np.uint8)
    labels[reach] = cv2.GC_PR_BGD
    labels[seed] = cv2.GC_PR_FGD
    labels[reach & background & ~seed] = cv2.GC_BGD
    labels[core] = cv2.GC_FGD
    if not core.any():  # a thin object: keep the depth's answer
        return seed
    x, y, w, h = cv2.boundingRect(reach.astype(np.uint8))  # the window: what GrabCut may take, and a band beyond
    top, left = max(0, y - band), max(0, x - band)
    bottom, right = min(seed.shape[0], y + h + band), min(seed.shape[1], x + w + band)
    cv2.setRNGSeed(0)
    refined = np.zeros(seed.shape, bool)
    refined[top:bottom, left:right] = grabcut_object(rgb[top:bottom, left:right], labels[top:bottom, left:right],
                                                     GRABCUT_ITERATIONS)  # the part that holds the core
    return refined


def depth_cut(view: ViewInput, refine: bool = True, seed: int = 0) -> DepthCut:
    """Cut the target out of ``view`` with its depth (needs ``depth`` and ``intrinsics``; ``gravity_up``
    and ``roi`` help). DepthSegmentationError says why depth cannot do it, for a fallback."""
    if view.depth is None or view.intrinsics is None:
        raise DepthSegmentationError("depth segmentation needs a depth image and the camera intrinsics")
    points, valid = backproject(view.depth, view.intrinsics)
    if valid.mean() < 0.05:
        raise DepthSegmentationError(f"only {100 * valid.mean():.0f} % of the depth image has readings")
    plane = support_plane(points[valid], view.gravity_up, np.random.default_rng(seed))
    height = plane.height(points)
    depth = np.where(valid, view.depth, 0.0)
    threshold = _tolerance(depth, MIN_HEIGHT, 0.015)
    nearest = _nearest_index(valid)
    count, labels = _pieces(valid & (height > threshold), depth, valid, nearest)
    known_height = height.ravel()[nearest]  # a hole has its nearest reading's height
    count, labels, apart = split_touching(labels, count, points, known_height, threshold + FOOT_BAND, view.rgb)
    labels = merge_carried_pieces(labels, count, known_height, points, valid, _tolerance(depth, SUPPORT_HEIGHT, 0.05),
                                  plane, apart)
    on_plane = valid & (np.abs(height) < _tolerance(depth, PLANE_TOLERANCE, 0.01))
    kept = drop_scenery(labels, count, known_height, plane)
    piece = target_piece(kept, count, view.roi)
    note = ""
    if view.roi is None and nearer_the_centre(labels & (kept == 0), piece):
        note = ("the piece nearest the image centre runs out of the image upwards and was left out as the room (an "
                "object cut off at the image's top?)")
    piece = _fill_holes(recover_base(piece, points, valid, height, plane, threshold))
    mask = grabcut_refine(view.rgb, piece, on_plane, ~valid) if refine else piece
    return DepthCut(mask=mask, depth_mask=piece, plane=plane, note=note)


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
