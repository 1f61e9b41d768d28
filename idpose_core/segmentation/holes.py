"""The target's holes closed, but for those the camera sees through: the table or the room behind a mug's
handle stays out of the mask, the inside of a cup seen from above and a gap without depth readings come in."""
from __future__ import annotations

import cv2
import numpy as np

from idpose_core.segmentation.footprint import BASE_SLICE, over_footprint
from idpose_core.segmentation.plane import Plane

SEEN_THROUGH_SHARE = 0.5  # of a hole's pixels: readings beyond the object this many, it is seen through


def seen_through(readings: np.ndarray, reading_height: np.ndarray, piece_points: np.ndarray,
                 piece_height: np.ndarray, plane: Plane, band: float) -> np.ndarray:
    """(N,) bool: which ``readings`` (N, 3) in a hole of the piece lie beyond the object: outside its footprint on
    the plane (the convex hull of ``piece_points`` (M, 3) seen from above: the room, the table behind it), or on the
    table (``reading_height`` (N,) within ``band`` m of the plane) outside the footprint of its base (its points up
    to ``BASE_SLICE`` above ``band``; ``piece_height`` (M,)): the table seen under a handle, not the bottom inside a
    cup."""
    if len(piece_points) < 3:
        return np.zeros(len(readings), bool)
    beyond = ~over_footprint(piece_points, readings, plane, 0.0)
    base = piece_points[piece_height <= band + BASE_SLICE]
    low = reading_height <= band
    if len(base) >= 3 and low.any():
        beyond[low] |= ~over_footprint(base, readings[low], plane, 0.0)
    return beyond


def close_holes(piece: np.ndarray, points: np.ndarray, valid: np.ndarray, height: np.ndarray, plane: Plane,
                band: np.ndarray) -> np.ndarray:
    """``piece`` (H, W) bool with every hole closed (what its outer contours enclose) but those whose readings
    mostly lie behind the piece around them and beyond the object (``seen_through``; ``points`` (H, W, 3),
    ``height`` and ``band`` (H, W) m): a hole without readings, showing the object's own inside, or filled by a part
    standing out in front of it (a head before a small body), is closed."""
    contours, _ = cv2.findContours(piece.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    filled = np.zeros(piece.shape, np.uint8)
    cv2.drawContours(filled, contours, -1, 1, thickness=cv2.FILLED)
    holes = filled.astype(bool) & ~piece
    if not holes.any():
        return piece
    own = piece & valid
    own_points, own_height, own_band = points[own], height[own], float(np.median(band[own]))
    count, labels = cv2.connectedComponents(holes.astype(np.uint8), connectivity=4)
    closed = piece | holes
    kernel = np.ones((3, 3), np.uint8)
    for hole in range(1, count):
        inside = labels == hole
        read = inside & valid
        rim = cv2.dilate(inside.astype(np.uint8), kernel, iterations=2).astype(bool) & own
        if not read.any() or not rim.any():
            continue
        behind = points[read][:, 2] > np.median(points[rim][:, 2])  # not a part standing out in front of the piece
        beyond = seen_through(points[read], height[read], own_points, own_height, plane, own_band)
        if (beyond & behind).sum() >= SEEN_THROUGH_SHARE * inside.sum():
            closed &= ~inside
    return closed
