"""GrabCut seeded from the depth cut: the colours settle the boundary that the depth leaves ragged, and give
back what a stereo camera does not read."""
from __future__ import annotations

import math

import cv2
import numpy as np

from idpose_core.grabcut import grabcut_object

GRABCUT_ITERATIONS = 4
GRABCUT_BAND = 0.04  # of the piece's bounding-box diagonal: how far outside its edge GrabCut may grow it
HOLE_REACH = 4  # GrabCut's band reaches this many times as far through pixels without a depth reading
CORE_MARGIN = 2  # px inside the piece's edge that GrabCut may take away (thin legs stay)


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
