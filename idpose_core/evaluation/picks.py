"""Which views are estimated together: seeded picks of 8 views from a pool, estimated on their first n."""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

PICK_SIZE = 8
VIEW_COUNTS = (2, 4, 6, 8)


class TooFewViews(ValueError):
    """The pool cannot hold any of the requested view sets; the message says how many views it has."""


def draw_picks(pool: Sequence[int], samples: int, seed: int, pick_size: int = PICK_SIZE) -> list[list[int]]:
    """``samples`` seeded random picks of ``min(pick_size, len(pool))`` distinct view ids, each sorted.

    Sorting keeps the capture order, so the first view of a pick (the anchor) is the one a robot
    would have taken first. Raises ValueError for fewer than 2 views or a non-positive sample count.
    """
    if len(pool) < 2:
        raise TooFewViews(f"need at least 2 usable views to evaluate, the pool has {len(pool)}")
    if samples < 1:
        raise ValueError(f"the number of samples must be at least 1, got {samples}")
    rng = np.random.default_rng(seed)
    size = min(pick_size, len(pool))
    return [sorted(int(v) for v in rng.choice(np.asarray(pool), size=size, replace=False)) for _ in range(samples)]


def usable_view_counts(requested: Sequence[int], pool_size: int) -> list[int]:
    """The requested view counts a pick from this pool can hold; ``TooFewViews`` when none can."""
    pick_size = min(PICK_SIZE, pool_size)
    counts = sorted({n for n in requested if n <= pick_size})
    if not counts:
        raise TooFewViews(f"only {pool_size} usable views: cannot evaluate sets of "
                          f"{', '.join(map(str, requested))} views")
    return counts
