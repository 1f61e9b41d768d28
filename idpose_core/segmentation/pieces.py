"""What stands above the plane split into pieces at depth jumps (a surface seen at a grazing angle is not a
jump), and the tests every later step asks of a piece: does it stand on the plane, does it leave the image."""
from __future__ import annotations

import cv2
import numpy as np

DEPTH_JUMP = 0.03  # relative depth step between neighbours that separates two pieces
SLANT_TOLERANCE = 0.5  # of a depth step: one within this of the steps either side continues a slanted surface
MIN_PIECE_SHARE = 0.002  # of the image: smaller pieces are noise
FOOT_SHARE = 0.004  # of a piece's readings that must lie within cut.SUPPORT_HEIGHT of the plane for it to stand on it
FOOT_PIXELS = 8  # ... and at least this many: a thin leg in sight is enough, a speck of noise is not


def connected_pieces(above: np.ndarray, depth: np.ndarray, valid: np.ndarray,
                     nearest: np.ndarray) -> tuple[int, np.ndarray]:
    """Connected pieces of ``above`` that no depth jump crosses: (count, labels). Holes in the depth (no reading)
    that ``above`` pixels close around count as part of the piece, each with its nearest reading's depth (``nearest``:
    ``nearest_index(valid)``): a stereo camera's shadow between an object and the wall behind it keeps the jump
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


def nearest_index(known: np.ndarray) -> np.ndarray:
    """(H, W) int: the flat index of the nearest ``known`` (H, W) bool pixel to each pixel (itself where known)."""
    _, nearest = cv2.distanceTransformWithLabels((~known).astype(np.uint8), cv2.DIST_L2, 5,
                                                 labelType=cv2.DIST_LABEL_PIXEL)
    lookup = np.zeros(int(nearest.max()) + 1, np.int64)
    lookup[nearest[known]] = np.flatnonzero(known)
    return lookup[nearest]


def stands(height: np.ndarray, support: np.ndarray) -> bool:
    """Whether a piece with these heights above the plane (N,) reaches it: at least ``FOOT_SHARE`` of its readings,
    and ``FOOT_PIXELS``, lie within ``support`` (N,) of it (a toy table's top with a leg in sight stands; a duck's
    head does not)."""
    low = int(np.count_nonzero(height <= support))
    return low >= max(FOOT_PIXELS, FOOT_SHARE * len(height))


def border_labels(labels: np.ndarray) -> np.ndarray:
    """The labels (sorted, unique) found on the image border: pieces that run out of the image."""
    return np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
