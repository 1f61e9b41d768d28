"""Pieces that belong to one object joined again: the legs that carry a table top, and a part that does not
reach the plane (a duck's head) with the piece it stands out in front of."""
from __future__ import annotations

import cv2
import numpy as np

from idpose_core.segmentation.colour import chromaticity, median_chromaticity, same_colour
from idpose_core.segmentation.footprint import over_footprint, rests_on
from idpose_core.segmentation.pieces import stands
from idpose_core.segmentation.plane import Plane, depth_tolerance
from idpose_core.segmentation.stacking import resting_top

ATTACH_GAP = 0.08  # m, or ATTACH_GAP_SHARE of the depth when larger: a carried piece's edge points lie this close
# to the piece carrying it (median); a head on a 20 cm body comes within 5 cm, a ball before a box that stands apart
# 13 cm or more; farther away the objects a camera frames are larger (a 1 m ball's marker stands 11 cm off at 1.1 m)
ATTACH_GAP_SHARE = 0.12  # of the median depth of the edge points (ATTACH_GAP)
CARRIER_INSET = 0.003  # m: a neighbour carries a piece from beneath when most of its points along their shared
# edge lie this far inside the piece's footprint (a table's legs under its top; a box behind the top lies outside)
MIN_SHARED_EDGE = 0.05  # of a carried piece's outline: it touches what carries it along more than this (a table
# top that touches a crate behind it at one corner is not carried by the crate)
GAP_POINTS = 400  # of each side, for the gap between two sets of points


def _gap(front: np.ndarray, back: np.ndarray) -> float:
    """Median distance (m) from the points ``front`` (N, 3) to their nearest among ``back`` (M, 3), on at
    most ``GAP_POINTS`` of each (evenly spaced)."""
    front = front[np.linspace(0, len(front) - 1, min(len(front), GAP_POINTS)).astype(int)]
    back = back[np.linspace(0, len(back) - 1, min(len(back), GAP_POINTS)).astype(int)]
    return float(np.median(np.min(np.linalg.norm(front[:, None] - back[None], axis=-1), axis=1)))


def _attach_gap(edge: np.ndarray) -> float:
    """The most a piece's ``edge`` points (N, 3) may lie from a piece they are attached to (m): ``ATTACH_GAP``, or
    its share of their median depth when larger."""
    return float(depth_tolerance(np.median(edge[:, 2]), ATTACH_GAP, ATTACH_GAP_SHARE))


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


def _whole_of(piece: int, inside: np.ndarray, labels: np.ndarray, areas: np.ndarray, standing: np.ndarray,
              points: np.ndarray, valid: np.ndarray, plane: Plane, chroma: np.ndarray, may_join) -> int:
    """The neighbour that a piece which does not stand (its pixels ``inside``) is a part of, or 0: one larger than
    it, or standing, that it shares more than ``MIN_SHARED_EDGE`` of its outline with and is attached to (its edge
    points within ``ATTACH_GAP`` of the neighbour's), where they meet standing out in front of it, or behind it
    and either resting on it (``rests_on``) or of its colour along the edge (``same_colour`` in ``chroma``: one
    object continued across a depth step); of several, the one with the longest shared edge."""
    kernel = np.ones((3, 3), np.uint8)
    ring = cv2.dilate(inside.astype(np.uint8), kernel, iterations=2).astype(bool) & ~inside
    neighbours, shared = np.unique(labels[ring], return_counts=True)
    best, best_shared = 0, 0
    for other, length in zip(neighbours, shared):
        if other == 0 or other == piece or not may_join(piece, other) or not (
                areas[other] > areas[piece] or standing[other]):
            continue
        edge = cv2.dilate((labels == other).astype(np.uint8), kernel, iterations=2).astype(bool) & inside & valid
        behind = ring & (labels == other) & valid
        if length <= max(best_shared, MIN_SHARED_EDGE * ring.sum()) or not edge.any() or not behind.any():
            continue
        in_front = np.median(points[edge][:, 2]) < np.median(points[behind][:, 2])
        if ((in_front or rests_on(points[inside & valid], points[(labels == other) & valid], plane)
             or same_colour(median_chromaticity(chroma, edge), median_chromaticity(chroma, behind)))
                and _gap(points[edge], points[behind]) < _attach_gap(points[edge])):
            best, best_shared = int(other), length
    return best


def merge_carried_pieces(labels: np.ndarray, count: int, height: np.ndarray, points: np.ndarray,
                         valid: np.ndarray, support: np.ndarray, plane: Plane, rgb: np.ndarray, up: np.ndarray,
                         apart: frozenset[tuple[int, int]] = frozenset(),
                         resting: frozenset[tuple[int, int]] = frozenset()
                         ) -> tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
    """(the labels, the pixels (H, W) bool of each piece that rests on another's top paired with that other's: the
    ``resting`` pairs given and those found here, as they were when kept apart) with every piece joined by the
    smaller ones that carry it from beneath (``_carriers_beneath``: a table top and its legs), then every piece that
    still does not reach the plane (``stands``: too few of its points within ``support`` (H, W), m) joined to the
    neighbouring piece it is a part of (``_whole_of``: it stands out in front of it, or rests on it or continues its
    colour behind it, attached; ``rgb`` (H, W, 3)), until none joins: a part of an object that a depth jump cut off
    (a duck's head and back, larger than the breast below them; a brick's studs seen from level, behind its front
    face, and the marker on them). A piece behind its neighbour and beyond its footprint stays apart (an object
    partly hidden by the target), and so does one that is well in front of it (a ball whose lowest visible points
    are high on its curve, before a box behind it). A piece that rests on the top of a standing piece of another
    colour (``resting_top``; ``up`` (H, W): the readings that face up) is another object, never joined to it (a duck
    on a box, apart from it in depth): it stands on that top, as the upper pieces of ``resting`` pairs (upper,
    carrier) do, and is nobody's part (not the wall's behind it). Pieces that ``apart`` pairs (``split_touching``:
    two objects) never join, nor do the pieces they have joined."""
    labels = labels.copy()
    chroma = chromaticity(rgb)
    owner = np.arange(count)  # the piece each original piece has joined
    kept_apart = set(apart)
    found = [(labels == upper, labels == carrier) for upper, carrier in resting]

    def may_join(piece: int, other: int) -> bool:
        return not any({owner[first], owner[second]} == {piece, other} for first, second in kept_apart)

    def rests_apart(upper: int, carrier: int) -> bool:
        """Whether ``upper`` rests on the top of ``carrier``, which stands, each of its own colour: two objects
        (``resting_top``), kept apart and recorded."""
        upper_pixels, carrier_pixels = labels == upper, labels == carrier
        if not standing[carrier] or same_colour(median_chromaticity(chroma, upper_pixels),
                                                median_chromaticity(chroma, carrier_pixels)):
            return False
        if resting_top(upper_pixels & valid, carrier_pixels & valid, points, height, up, plane) is None:
            return False
        kept_apart.add((upper, carrier))
        found.append((upper_pixels, carrier_pixels))
        standing[upper] = True  # on the carrier's top
        return True

    kernel = np.ones((3, 3), np.uint8)
    areas = np.bincount(labels.ravel(), minlength=count)
    standing = np.zeros(count, bool)
    for piece in np.flatnonzero(areas):
        inside = labels == piece
        standing[piece] = stands(height[inside], support[inside])
    standing[[upper for upper, _ in resting]] = True  # on a carrier's top
    for piece in np.argsort(areas)[::-1]:  # what stands beneath a piece, smaller than it, joins it (its legs)
        if piece == 0 or areas[piece] == 0:
            continue
        inside = labels == piece
        ring = cv2.dilate(inside.astype(np.uint8), kernel, iterations=2).astype(bool) & ~inside
        for other in _carriers_beneath(piece, inside, ring, labels, height, points, valid, plane):
            if areas[other] < areas[piece] and may_join(piece, other) and not rests_apart(piece, other):
                labels[labels == other] = piece
                owner[owner == other] = piece
                areas[piece] += areas[other]
                areas[other] = 0
                standing[piece] |= standing[other]
    joined = True
    while joined:  # again after a join: a part on a part (a marker on a brick's studs) joins once they have
        joined = False
        for piece in np.argsort(areas):  # smallest first: a head joins its body before the body is judged
            if piece == 0 or areas[piece] == 0 or standing[piece]:
                continue
            inside = labels == piece
            best = _whole_of(piece, inside, labels, areas, standing, points, valid, plane, chroma, may_join)
            if best and not rests_apart(piece, best):  # a duck on a box is its own object, nobody's part
                labels[inside] = best
                owner[owner == piece] = best
                areas[best] += areas[piece]
                areas[piece] = 0
                joined = True
    return labels, found
