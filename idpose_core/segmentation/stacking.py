"""One object resting on another's top (a duck on a box, a block on a desk): two objects of two colours, met at a
crease, apart in depth, or at the carrier's raised top. The target keeps what rests on it and leaves out what it rests
on, as it leaves out the table."""
from __future__ import annotations

import cv2
import numpy as np

from idpose_core.segmentation.footprint import rests_on
from idpose_core.segmentation.pieces import FOOT_PIXELS, MIN_PIECE_SHARE
from idpose_core.segmentation.plane import Plane, depth_tolerance

REST_TOLERANCE = 0.01  # m, or REST_TOLERANCE_SHARE of the depth when larger: an object resting on another's top has
# its lowest readings (5th percentile) no lower than this under that top (on 12 objects on boxes: 2-43 mm above)
REST_TOLERANCE_SHARE = 0.02
TOP_REACH = 8  # px: the carrier's top shows this close to what rests on it


def resting_top(upper: np.ndarray, carrier: np.ndarray, points: np.ndarray, height: np.ndarray, up: np.ndarray,
                plane: Plane) -> float | None:
    """The height (m above the plane, with ``REST_TOLERANCE``) of the top of the part ``carrier`` (H, W) bool that
    the part ``upper`` (H, W) bool rests on, or None when it does not: at least ``FOOT_PIXELS`` of the carrier's
    readings within ``TOP_REACH`` px of the upper part face up (``up`` (H, W)); the upper part's lowest readings
    (5th percentile of ``height`` (H, W)) lie no lower than ``REST_TOLERANCE`` under the carrier's top (the median
    height of its readings that face up); and the upper part's base (its readings within twice that of its lowest)
    lies over the carrier's footprint (``rests_on``; the carrier's top is hidden behind what rests on it, its sides
    are not)."""
    top = carrier & up
    reach = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * TOP_REACH + 1,) * 2)
    if (cv2.dilate(upper.astype(np.uint8), reach).astype(bool) & top).sum() < FOOT_PIXELS:
        return None
    surface = float(np.median(height[top]))  # the whole top: what faces up near the upper part may be its own lap
    tolerance = float(depth_tolerance(np.median(points[top][:, 2]), REST_TOLERANCE, REST_TOLERANCE_SHARE))
    lowest = float(np.percentile(height[upper], 5))
    base = upper & (height <= lowest + 2 * tolerance)  # its lowest in sight: its side may overhang the top
    if lowest < surface - tolerance or base.sum() < FOOT_PIXELS or not rests_on(points[base], points[carrier], plane):
        return None
    return surface + tolerance


def split_at_raised_top(piece: np.ndarray, points: np.ndarray, height: np.ndarray, up: np.ndarray
                        ) -> np.ndarray | None:
    """(H, W) int: ``piece`` (H, W) bool cut at its raised top, 1 up to it and 2 above (0 elsewhere), or None: the
    top is the height (``height`` (H, W), m above the plane) where most of the piece's readings that face up (``up``
    (H, W)) lie, within ``REST_TOLERANCE``; both sides need ``MIN_PIECE_SHARE`` of the image, and with no crease to
    say where one object ends, the side below at least as many pixels as the side above (a box shows no less of
    itself than what stands on it; a toy's flat base of another colour does). A box's top with something on it, when
    no crease parts them (a stereo camera's noise folds a bumpy object all over)."""
    readings = piece & up
    least = MIN_PIECE_SHARE * piece.size
    if readings.sum() < least:
        return None
    tolerance = float(depth_tolerance(np.median(points[readings][:, 2]), REST_TOLERANCE, REST_TOLERANCE_SHARE))
    levels = np.floor(height[readings] / tolerance).astype(int)
    values, counts = np.unique(levels, return_counts=True)
    top = (values[np.argmax(counts)] + 1) * tolerance + tolerance  # the fullest band's upper edge, and the margin
    above = piece & (height > top)
    if above.sum() < least or (piece & ~above).sum() < max(least, above.sum()):
        return None
    return np.where(piece, np.where(above, 2, 1), 0)


def lifted_off(upper: np.ndarray, carrier: np.ndarray, height: np.ndarray, top: float) -> np.ndarray:
    """(H, W) bool: the pixels of ``carrier`` (H, W) bool higher than its ``top`` (m, ``resting_top``) that connect to
    ``upper`` (H, W) bool: what rests on the top, not the carrier (a teddy's seat, a desk's legs, torn from the part
    they rest on by the creases between them)."""
    count, pieces = cv2.connectedComponents((carrier & (height > top)).astype(np.uint8), connectivity=4)
    touching = np.unique(pieces[cv2.dilate(upper.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)])
    return np.isin(pieces, touching[touching > 0])


def about_the_carrier(upper: np.ndarray, carrier: np.ndarray) -> bool:
    """Whether a view without a region of interest is about the carrier rather than what rests on it: some pixel of
    ``carrier`` (H, W) bool is as near the image centre as the centroid of ``upper`` (H, W) bool (a brick seen from
    above, a marker on its studs nearer the centre; a duck framed on its box covers the centre itself)."""
    centre = (np.array(upper.shape) - 1) / 2.0
    upper_offset = np.linalg.norm(np.argwhere(upper).mean(axis=0) - centre)
    return bool(np.min(np.linalg.norm(np.argwhere(carrier) - centre, axis=1)) <= upper_offset)


def with_what_it_carries(piece: np.ndarray, labels: np.ndarray, resting: list[tuple[np.ndarray, np.ndarray]],
                         roi: tuple[int, int, int, int] | None) -> tuple[np.ndarray, np.ndarray]:
    """(the target's piece with what rests on it, what the target rests on), both (H, W) bool: ``piece`` (H, W) is
    the target's piece among ``labels`` (H, W); ``resting`` pairs the pixels (H, W) bool of a part that rests on
    another's top with that other's, as cut apart (each has since joined a piece of ``labels``). Without a region of
    interest (``roi``) a view the centre rule gave to what rests on the carrier goes to the carrier when it is about
    it (``about_the_carrier``)."""
    label = int(labels[piece][0])
    pairs = [(int(labels[upper][0]), int(labels[carrier][0])) for upper, carrier in resting]  # their labels now
    for upper_label, carrier_label in pairs:
        if roi is None and upper_label == label != carrier_label and about_the_carrier(
                labels == upper_label, labels == carrier_label):
            label = carrier_label
    piece = labels == label
    support = np.zeros_like(piece)
    for upper_label, carrier_label in pairs:
        if carrier_label == label != upper_label:
            piece = piece | (labels == upper_label)
        elif upper_label == label != carrier_label:
            support |= labels == carrier_label
    return piece, support
