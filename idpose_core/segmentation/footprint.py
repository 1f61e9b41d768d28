"""An object's footprint on the support plane: which readings lie over it, which face up (the table), and the
base the height test leaves out."""
from __future__ import annotations

import math

import cv2
import numpy as np

from idpose_core.segmentation.normals import surface_normals
from idpose_core.segmentation.plane import Plane, depth_tolerance

BASE_MARGIN = 0.002  # m, or 0.4 % of the depth when larger: how far outside the piece's footprint on the plane a
# reading may lie and still be the piece's base (the band under ``cut.MIN_HEIGHT`` that the height test leaves out)
FOOTPRINT_CELL = 0.001  # m: the grid the footprint is drawn on
BASE_SLICE = 0.02  # m above the height threshold: the piece's points that draw its footprint (higher up, an
# overhang such as a duck's head covers table that shows beneath it)
REST_MARGIN = 0.01  # m: a part resting on a piece lies over its footprint grown by this (a head overhangs a little)
TABLE_TILT_DEG = 35.0  # a reading whose surface tilts less than this from the plane's normal faces up: the table
# (under a rounded bottom, inside the footprint), not the object's side or underside


def _plane_basis(plane: Plane) -> np.ndarray:
    """(2, 3): two unit vectors spanning the plane, orthogonal to each other and to its normal."""
    seed = np.eye(3)[int(np.argmin(np.abs(plane.normal)))]
    first = np.cross(plane.normal, seed)
    first /= np.linalg.norm(first)
    return np.stack([first, np.cross(plane.normal, first)])


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


def rests_on(piece_points: np.ndarray, other_points: np.ndarray, plane: Plane) -> bool:
    """Whether most of ``piece_points`` (N, 3) lie over the footprint of ``other_points`` (M, 3) on the plane, grown
    by ``REST_MARGIN``: on top of the other piece (a brick's studs, a duck's head seen from low, a duck on a box),
    not beside or behind it (which stands beyond its footprint)."""
    if len(piece_points) < 3 or len(other_points) < 3:
        return False
    return bool(over_footprint(other_points, piece_points, plane, REST_MARGIN).mean() > 0.5)


def faces_up(points: np.ndarray, valid: np.ndarray, plane: Plane) -> np.ndarray:
    """(H, W) bool: the surface at each reading tilts less than ``TABLE_TILT_DEG`` from the plane's normal
    (``surface_normals``; False where a neighbour has no reading)."""
    normal, holds = surface_normals(points, valid.astype(np.int32))
    return holds & (np.abs(normal @ plane.normal) > math.cos(math.radians(TABLE_TILT_DEG)))


def recover_base(piece: np.ndarray, points: np.ndarray, valid: np.ndarray, height: np.ndarray, plane: Plane,
                 band: np.ndarray, up: np.ndarray) -> np.ndarray:
    """The piece (H, W) bool with its base: the readings under the height test's threshold (``band`` (H, W), m)
    whose surface does not face up (``up`` (H, W), ``faces_up``: the table) and that lie over the piece's footprint
    on the plane (the convex hull, seen from above, of its points up to ``BASE_SLICE`` higher, grown by
    ``BASE_MARGIN``) and connect to it in the image: the bottom centimetre of the object, which the height test
    cannot tell from the table."""
    footing = points[piece & valid & (height <= band + BASE_SLICE)]
    if len(footing) < 3:
        return piece
    low = valid & ~piece & (height <= band) & (height > -band) & ~up
    margin = float(np.max(depth_tolerance(points[..., 2][piece & valid], BASE_MARGIN, 0.004)))
    rows, cols = np.nonzero(low)
    over = over_footprint(footing, points[rows, cols], plane, margin)
    base = np.zeros_like(piece)
    base[rows[over], cols[over]] = True
    count, labels = cv2.connectedComponents((piece | base).astype(np.uint8), connectivity=4)
    kept = np.unique(labels[piece])
    return np.isin(labels, kept[kept > 0])
