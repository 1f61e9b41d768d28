"""The target's piece among those left: the room (a wall that rises out of the image) left out, then the one
in the region of interest, else the one nearest the image centre."""
from __future__ import annotations

import math

import numpy as np

from idpose_core.segmentation.errors import DepthSegmentationError
from idpose_core.segmentation.pieces import MIN_PIECE_SHARE, border_labels
from idpose_core.segmentation.plane import Plane

CENTRE_MARGIN = 0.05  # of the image size: pieces this much farther from the centre than the nearest one compete
SCENERY_TOP_SHARE = 0.9  # of a piece's top height: its readings on the image border reach this high, it runs out of
# the image upwards (a wall, the room), not an object standing in view
ROOM_HEIGHT = 0.3  # m above the plane: a piece this low is an object even where the image cuts its top off
UP_BORDER_COSINE = 0.3  # a border is an upper one when the up direction's image direction points this much at it


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
