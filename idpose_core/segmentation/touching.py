"""Pieces cut apart where two objects touch without a depth jump: along concave creases and thin necks, kept
apart only when the parts differ in colour and both stand on the plane, or one rests on the other's top."""
from __future__ import annotations

import math

import cv2
import numpy as np

from idpose_core.segmentation.colour import chromaticity, median_chromaticity, same_colour
from idpose_core.segmentation.normals import surface_normals
from idpose_core.segmentation.pieces import MIN_PIECE_SHARE, border_labels, nearest_index, stands
from idpose_core.segmentation.plane import Plane
from idpose_core.segmentation.stacking import lifted_off, resting_top, split_at_raised_top

CREASE_STEP = 4  # px either side of a reading: the two surface points a concave crease is judged between
CREASE_NORMAL_STEP = 2  # px either side for their normals' finite differences
CREASE_SMOOTHING = 0.01  # m: the points are smoothed over neighbours this close in 3-D before the normals are taken
CREASE_ANGLE_DEG = 35.0  # the two normals differ by more than this at a crease
NECK_RADIUS = 3  # px: a piece narrower than a disc this wide is cut there too (then joined again unless the
# two sides are two objects, as at a concave fold)


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


def _nearest_fill(seeds: np.ndarray, region: np.ndarray) -> np.ndarray:
    """``seeds`` (H, W) int (0: unlabelled) with every pixel of ``region`` (H, W) bool given the label of the nearest
    seed."""
    return np.where(region, seeds.ravel()[nearest_index(seeds != 0)], seeds)


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
                   rgb: np.ndarray, valid: np.ndarray, up: np.ndarray, plane: Plane
                   ) -> tuple[int, np.ndarray, frozenset[tuple[int, int]], frozenset[tuple[int, int]]]:
    """(count, labels, the pairs of labels cut apart, the pairs (upper, carrier) of those where one rests on the
    other's top) with pieces cut apart where two objects touch without a depth jump. A piece is cut along its
    concave creases (``concave_creases``) and its thin necks (``_opened``) into parts (smaller ones, and the cut,
    go to the nearest large part); two neighbouring parts whose median chromaticities differ by more than
    ``OBJECT_CHROMA_DELTA`` stay apart when each stands on the plane by itself (``stands``: its ``height`` (H, W)
    under ``footing`` (H, W)): two objects side by side (a box against a toy table's top); or when one stands and
    the other rests on its top (``resting_top``: a duck on a box, a block on a desk; ``valid`` (H, W): the readings,
    ``up`` (H, W): those that face up, ``faces_up`` on the support ``plane``; what of the carrier stands above its
    top goes to the part resting there, ``lifted_off``). Otherwise they join again: a duck's head and body (one
    stands), a marker on a ball, a table's legs and top (too thin to be a large part). A piece its creases do not cut
    into two large parts is cut at its raised top instead (``split_at_raised_top``) and judged the same way. A piece
    that runs out of the image is left whole: what lies beyond cannot be judged (a wall behind the table, its tiles
    in different colours)."""
    crease = cv2.dilate(concave_creases(points, labels).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    crease |= (labels > 0) & ~_opened(labels)  # a cut with no gaps, and the thin necks where two objects meet
    cut_pairs: set[tuple[int, int]] = set()
    resting: set[tuple[int, int]] = set()
    if not crease.any():
        return count, labels, frozenset(cut_pairs), frozenset(resting)
    chroma = chromaticity(rgb)
    labels = labels.copy()
    reach = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (4 * CREASE_STEP + 1,) * 2)
    for piece in np.setdiff1d(np.unique(labels[crease & (labels > 0)]), border_labels(labels)):
        inside = labels == piece
        parts_count, parts = cv2.connectedComponents((inside & ~crease).astype(np.uint8), connectivity=4)
        areas = np.bincount(parts.ravel(), minlength=parts_count)
        large = [part for part in range(1, parts_count) if areas[part] >= MIN_PIECE_SHARE * labels.size]
        if len(large) >= 2:
            parts = _nearest_fill(_grown(np.where(np.isin(parts, large), parts, 0), inside), inside)
        else:  # creases everywhere (a stereo camera's noise on a bumpy object) or none: cut at a raised top, if any
            parts = split_at_raised_top(inside, points, height, up & valid)
            if parts is None:
                continue
            areas, large = np.bincount(parts.ravel(), minlength=3), [1, 2]
        alone = {part: stands(height[parts == part], footing[parts == part]) for part in large}
        colour = {part: median_chromaticity(chroma, parts == part) for part in large}
        group = {part: part for part in large}
        mixed = []  # neighbours of two colours, one standing: one may rest on the other's top
        for part in large:
            near = cv2.dilate((parts == part).astype(np.uint8), reach).astype(bool) & inside
            for other in (int(other) for other in np.unique(parts[near]) if other > part):
                if same_colour(colour[part], colour[other]) or not (alone[part] or alone[other]):
                    _union(group, part, other)
                elif alone[part] != alone[other]:
                    mixed.append((other, part) if alone[part] else (part, other))
        stacked = _stacked_groups(mixed, group, parts, points, height, valid, up, plane)
        roots = sorted({_root(group, part) for part in large}, key=lambda root: -areas[root])
        new = [int(piece)] + [count + index for index in range(len(roots) - 1)]
        for label, root in zip(new[1:], roots[1:]):
            labels[inside & np.isin(parts, _members(group, root))] = label
        label_of = dict(zip(roots, new))
        resting |= {(label_of[_root(group, upper)], label_of[_root(group, carrier)]) for upper, carrier in stacked
                    if _root(group, upper) != _root(group, carrier)}
        cut_pairs |= {(first, second) for index, first in enumerate(new) for second in new[index + 1:]}
        count += len(roots) - 1
    return count, labels, frozenset(cut_pairs), frozenset(resting)


def _stacked_groups(mixed: list[tuple[int, int]], group: dict[int, int], parts: np.ndarray, points: np.ndarray,
                    height: np.ndarray, valid: np.ndarray, up: np.ndarray, plane: Plane) -> set[tuple[int, int]]:
    """The pairs (upper, carrier) of ``mixed`` pairs of parts (``parts`` (H, W) labels) whose groups (``group``,
    joined by colour so far) are two objects, the upper one resting on the carrier's top (``resting_top``: a duck,
    head and body, on a box); what of the carrier stands above its top goes to the upper part (``lifted_off``, in
    ``parts``). The groups of every other pair are joined (a duck's head on its body)."""
    stacked = set()
    for upper, carrier in mixed:
        if _root(group, upper) == _root(group, carrier):
            continue
        upper_pixels, carrier_pixels = (np.isin(parts, _members(group, side)) for side in (upper, carrier))
        top = resting_top(upper_pixels & valid, carrier_pixels & valid, points, height, up, plane)
        if top is None:
            _union(group, upper, carrier)
        else:
            stacked.add((upper, carrier))
            parts[lifted_off(upper_pixels, carrier_pixels, height, top)] = upper
    return stacked


def _members(group: dict[int, int], part: int) -> list[int]:
    """The parts in ``part``'s group."""
    return [member for member in group if _root(group, member) == _root(group, part)]


def _root(group: dict[int, int], part: int) -> int:
    """The representative of ``part``'s group (union-find)."""
    while group[part] != part:
        part = group[part]
    return part


def _union(group: dict[int, int], first: int, second: int) -> None:
    """Join the groups of ``first`` and ``second``."""
    group[_root(group, second)] = _root(group, first)
