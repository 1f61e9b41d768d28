"""One estimate of the protocol: estimate the task's views, score them, and run the baselines on the same views."""
from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from idpose_core.baselines import BASELINES, run_baseline
from idpose_core.baselines.scoring import score_baseline
from idpose_core.cameras import c2w_to_spherical
from idpose_core.evaluation.estimator import ViewSetEstimate, ViewSetEstimator
from idpose_core.evaluation.object_frame import world_cameras
from idpose_core.evaluation.protocol import EstimateTask
from idpose_core.evaluation.scoring import random_baseline, score_poses
from idpose_core.pipeline import ANCHOR_POLAR_RANGE_DEG
from idpose_core.solver import Progress
from idpose_core.view_input import ViewInput


@dataclass(frozen=True)
class EstimateOutcome:
    """What one estimate adds to the evaluation: pair records, random-baseline records, the estimate's row,
    the predicted cameras (n, 4, 4), the anchor's true one first, per classical baseline its (pair
    records, row) on the same views, and the estimator's answer itself (its masks and crops, when it has them)."""

    records: list[dict[str, Any]]
    random_records: list[dict[str, Any]]
    row: dict[str, Any]
    predicted_c2w: np.ndarray
    baselines: dict[str, tuple[list[dict[str, Any]], dict[str, Any]]] = field(default_factory=dict)
    estimate: ViewSetEstimate | None = None


def check_baselines(names: Sequence[str]) -> None:
    """ValueError naming the first unknown classical baseline."""
    unknown = [name for name in names if name not in BASELINES]
    if unknown:
        raise ValueError(f"unknown baseline {unknown[0]!r}: choose from {', '.join(BASELINES)}")


def anchor_geometry(true_c2w: np.ndarray) -> tuple[float, float]:
    """(polar angle in degrees, clipped to the range the node accepts so that every estimator agrees; distance)
    of the anchor camera (``true_c2w[0]``, OpenGL camera-to-world in the object frame)."""
    low, high = ANCHOR_POLAR_RANGE_DEG
    polar, _, distance = c2w_to_spherical(true_c2w[0])
    return float(np.clip(math.degrees(polar), low, high)), float(distance)


def run_estimate(estimator: ViewSetEstimator, task: EstimateTask, views: Sequence[ViewInput],
                 progress: Progress | None = None, baselines: Sequence[str] = ()) -> EstimateOutcome:
    """Estimate the task's views (its first n, anchor first, decoded once) and score them against the truth;
    then the same for each named classical baseline (``idpose_core.baselines.BASELINES``)."""
    true_c2w = task.true_c2w[:task.n]
    anchor_polar_deg, distance = anchor_geometry(true_c2w)
    estimate = estimator(views, anchor_polar_deg, distance, progress)
    records = [{"sample": task.sample, "n": task.n, "anchor_view": task.pick[0], "view": target, **record,
                "score": float(score), "ambiguous": bool(ambiguous), "seconds": estimate.seconds}
               for target, record, score, ambiguous in zip(task.pick[1:task.n], score_poses(estimate.poses, true_c2w),
                                                           estimate.scores, estimate.ambiguous)]
    row = {"sample": task.sample, "n": task.n, "views": list(task.views), "seconds": estimate.seconds,
           "anchor_polar_deg": anchor_polar_deg, "object_distance": distance, "details": estimate.details}
    predicted = world_cameras(estimate.poses, true_c2w[0])
    return EstimateOutcome(records, random_baseline(true_c2w, task.baseline_seed), row, predicted,
                           {name: classical_baseline(name, task, views) for name in baselines}, estimate)


def classical_baseline(name: str, task: EstimateTask, views: Sequence[ViewInput]
                       ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """(pair records, row) of the baseline ``name`` on the task's views (their intrinsics from the anchor's, when
    known); a view it cannot place gets a random guess (``score_baseline``) seeded by the task and the anchor
    image, so that bags of different objects seen from the same cameras draw different guesses."""
    true_c2w = task.true_c2w[:task.n]
    anchor_polar_deg, distance = anchor_geometry(true_c2w)
    estimate = run_baseline(name, [(view.rgb, view.alpha) for view in views], views[0].intrinsics, distance)
    rng = np.random.default_rng([task.seed, task.index, task.n, 1 + list(BASELINES).index(name),
                                 zlib.crc32(np.ascontiguousarray(views[0].rgb).tobytes())])
    records = [{"sample": task.sample, "n": task.n, "anchor_view": task.pick[0], "view": target, **record,
                "seconds": estimate.seconds}
               for target, record in zip(task.pick[1:task.n], score_baseline(
                   estimate, true_c2w, math.radians(anchor_polar_deg), distance, rng))]
    row = {"sample": task.sample, "n": task.n, "views": list(task.views), "status": estimate.status,
           "registered": [int(v) for v, ok in zip(task.pick, estimate.registered) if ok], "seconds": estimate.seconds}
    return records, row
