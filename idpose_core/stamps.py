"""Stamp matching: which message of a stream belongs to a view, by the nearest header stamp."""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

INPUT_TOLERANCE_S = 0.02  # largest stamp difference between an image and its depth, mask or gravity reading


def match_stamps(queries: Sequence[int], stamps: Sequence[int], tolerance: int) -> np.ndarray:
    """Index (N,) of the stamp nearest to each query within ``tolerance`` (same unit), or -1 when none is."""
    queries = np.asarray(queries, dtype=np.int64)
    stamps = np.asarray(stamps, dtype=np.int64)
    if stamps.size == 0:
        return np.full(queries.shape, -1, dtype=np.int64)
    order = np.argsort(stamps, kind="stable")
    ordered = stamps[order]
    right = np.clip(np.searchsorted(ordered, queries), 0, len(ordered) - 1)
    left = np.clip(right - 1, 0, len(ordered) - 1)
    nearest = np.where(np.abs(ordered[left] - queries) <= np.abs(ordered[right] - queries), left, right)
    found = np.abs(ordered[nearest] - queries) <= tolerance
    return np.where(found, order[nearest], -1)
