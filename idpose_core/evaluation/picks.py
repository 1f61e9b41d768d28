"""Which views are estimated together: seeded picks of 8 views from a pool, estimated on their first n."""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

PICK_SIZE = 8
VIEW_COUNTS = (2, 4, 6, 8)


class TooFewViews(ValueError):
    """The pool cannot hold any of the requested view sets; the message says how many views it has."""


def distinct_pair_count(pool_size: int) -> int:
    """How many different pairs of views a pool of ``pool_size`` views holds: the most picks ``draw_picks`` gives."""
    return math.comb(pool_size, 2)


def draw_picks(pool: Sequence[int], samples: int, seed: int, pick_size: int = PICK_SIZE) -> list[list[int]]:
    """Seeded picks of ``min(pick_size, len(pool))`` distinct view ids, each starting with a different pair.

    Each pick opens with a pair of views no other pick opens with, in capture order (the anchor is the one a robot
    took first), then the rest of the pick, drawn from the other views, in capture order. So the estimates on two
    views never score the same pair twice: a pool holding fewer pairs than ``samples`` gives one pick per pair
    (``distinct_pair_count``), not repeats. Raises ``TooFewViews`` for fewer than 2 views, ValueError for a
    non-positive sample count.
    """
    if len(pool) < 2:
        raise TooFewViews(f"need at least 2 usable views to evaluate, the pool has {len(pool)}")
    if samples < 1:
        raise ValueError(f"the number of samples must be at least 1, got {samples}")
    rng = np.random.default_rng(seed)
    views = sorted(int(v) for v in pool)
    size = min(pick_size, len(views))
    first, second = np.triu_indices(len(views), k=1)
    picks = []
    for index in rng.permutation(first.size)[:samples]:
        opening = [views[first[index]], views[second[index]]]
        others = [v for v in views if v not in opening]
        picks.append(opening + sorted(int(v) for v in rng.choice(others, size=size - 2, replace=False)))
    return picks


def usable_view_counts(requested: Sequence[int], pool_size: int) -> list[int]:
    """The requested view counts a pick from this pool can hold; ``TooFewViews`` when none can."""
    pick_size = min(PICK_SIZE, pool_size)
    counts = sorted({n for n in requested if n <= pick_size})
    if not counts:
        raise TooFewViews(f"only {pool_size} usable views: cannot evaluate sets of "
                          f"{', '.join(map(str, requested))} views")
    return counts
