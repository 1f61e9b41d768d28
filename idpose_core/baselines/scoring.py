"""A baseline's estimate scored as ID-Pose's: its camera poses in the anchor frame, the paper's errors.

A view the baseline could not place gets one uniform random guess on the sphere at the anchor's distance,
scored like any other: a failure then counts as much as guessing does (the random-pose row), neither
dropped from the accuracy (which would reward failing on hard views) nor given the worst possible error.
"""
from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from idpose_core.baselines.result import CONVERGED, FEWER, BaselineEstimate
from idpose_core.cameras import anchor_frame_poses, c2w_to_spherical
from idpose_core.evaluation.scoring import score_poses
from idpose_core.metrics import random_relative_poses


def score_baseline(estimate: BaselineEstimate, true_c2w: np.ndarray, anchor_polar: float, object_distance: float,
                   rng: np.random.Generator) -> list[dict[str, Any]]:
    """Per target view (1..n-1): ``score_poses``'s record plus ``registered``; unregistered views are guessed.

    ``true_c2w`` (n, 4, 4) OpenGL camera-to-world in the object frame, anchor first; a guess is placed in the
    anchor's frame as ``anchor_frame_poses`` places ID-Pose's relative poses (anchor at ``anchor_polar`` rad,
    ``object_distance`` from the object).
    """
    registered = np.asarray(estimate.registered, dtype=bool)
    guesses = random_relative_poses(c2w_to_spherical(true_c2w[0]), (len(registered) - 1,), rng)
    guessed = anchor_frame_poses(guesses, anchor_polar, object_distance)
    poses = np.where(registered[:, None, None], np.asarray(estimate.poses, dtype=np.float64), guessed)
    return [{**record, "registered": bool(placed)} for record, placed in zip(score_poses(poses, true_c2w),
                                                                             registered[1:])]


def estimate_summary(rows: Iterable[Mapping[str, Any]]) -> dict[str, dict[str, float | int]]:
    """Per view count n (keys ``str(n)`` in order, then ``"all"``): ``estimates`` (C) and ``mean_seconds``; for
    rows with a ``status``, also ``converged`` (A: every view registered) and ``fewer`` (B: only a retry with
    fewer views succeeded), the paper's "A + B of C"."""
    groups: dict[int, list[Mapping[str, Any]]] = defaultdict(list)
    for row in rows:
        groups[int(row["n"])].append(row)

    def summary(group: list[Mapping[str, Any]]) -> dict[str, float | int]:
        result: dict[str, float | int] = {"estimates": len(group),
                                          "mean_seconds": float(np.mean([row["seconds"] for row in group]))}
        if all("status" in row for row in group):
            result["converged"] = sum(row["status"] == CONVERGED for row in group)
            result["fewer"] = sum(row["status"] == FEWER for row in group)
        return result

    return {**{str(n): summary(groups[n]) for n in sorted(groups)},
            "all": summary([row for n in sorted(groups) for row in groups[n]])}
