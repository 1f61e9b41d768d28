"""The protocol's plan: seeded picks of a pool of posed views, each estimated on its first n views."""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from idpose_core.evaluation.object_frame import object_frame_c2w
from idpose_core.evaluation.picks import VIEW_COUNTS, draw_picks, usable_view_counts

WORLD_UP = (0.0, 0.0, 1.0)
OBJECT_CENTER = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class EvaluationProtocol:
    """``samples`` seeded picks of up to 8 views, each estimated on its first n views for n in ``view_counts``."""

    samples: int = 5
    seed: int = 0
    view_counts: tuple[int, ...] = VIEW_COUNTS


@dataclass(frozen=True)
class EstimateTask:
    """One estimate of the protocol: the first ``n`` views of pick ``sample`` (``pick``: view ids, anchor first),
    with the true cameras of the whole pick (``true_c2w`` (k, 4, 4), OpenGL, object frame); ``index`` is its
    place in the run, which with ``seed`` seeds its random baseline."""

    sample: int
    index: int
    pick: tuple[int, ...]
    n: int
    true_c2w: np.ndarray
    seed: int

    @property
    def views(self) -> tuple[int, ...]:
        """The view ids this estimate uses, anchor first."""
        return self.pick[:self.n]

    @property
    def baseline_seed(self) -> tuple[int, int, int]:
        """The seed of this estimate's random-pose baseline: the same wherever and whenever it runs."""
        return self.seed, self.index, self.n


def tasks_for_picks(picks: Sequence[Sequence[int]], true_cameras: Sequence[np.ndarray], view_counts: Sequence[int],
                    seed: int) -> list[EstimateTask]:
    """Each pick (view ids, anchor first; ``true_cameras``: its (k, 4, 4) OpenGL cameras in the object frame)
    estimated on its first n views for every n of ``view_counts`` it holds, in order; ``seed`` seeds the
    random baselines. Whoever chose the picks (seeded draws from a pool, fixed samples of a data set)."""
    tasks: list[EstimateTask] = []
    for sample, (pick, true_c2w) in enumerate(zip(picks, true_cameras, strict=True)):
        counts = [n for n in view_counts if n <= len(pick)]
        tasks += [EstimateTask(sample, len(tasks) + k, tuple(pick), n, true_c2w, seed) for k, n in enumerate(counts)]
    return tasks


def plan_tasks(world_from_camera: Mapping[int, np.ndarray], protocol: EvaluationProtocol,
               object_center: Sequence[float] = OBJECT_CENTER, up: Sequence[float] = WORLD_UP) -> list[EstimateTask]:
    """The protocol's estimates on a pool of posed views (view id -> the camera's optical frame in the world,
    (4, 4)), in order: each seeded pick with each usable view count. ``TooFewViews`` when the pool is too small."""
    pool = sorted(world_from_camera)
    picks = draw_picks(pool, protocol.samples, protocol.seed)
    counts = usable_view_counts(protocol.view_counts, len(pool))
    cameras = [object_frame_c2w(np.stack([world_from_camera[v] for v in pick]), object_center, up) for pick in picks]
    return tasks_for_picks(picks, cameras, counts, protocol.seed)
