"""Several views' poses chosen jointly: every pair's ranked hypotheses, composed through the views between.

A wide pair (little overlap) is settled through a view between: view k's candidates are its own pair's with the
anchor, and every other view's chosen pose composed with the hypotheses of that view's pair with k. Each
candidate is scored against every view already placed, and the best wins; the runner-up is the best candidate of
another cluster. With more than two views, every pair that agrees with the placement then enters a pose graph
(``pose_graph``), whose fit sets the poses and whose loop-closure residual measures how well the views agree.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from idpose_core.pose_hypotheses.hypothesis import ScoredHypothesis, Source
from idpose_core.pose_hypotheses.pair import PairRanking, clusters_of
from idpose_core.pose_hypotheses.pose_graph import agreeing_edges, optimise
from idpose_core.pose_hypotheses.verifier import ViewEvidence, verify

ROUNDS = 2  # passes over the views: a later pass sees every view placed


@dataclass(frozen=True)
class ChosenPose:
    """One view's pose in the anchor's frame (``pose`` (4, 4)), the ``source`` of the hypothesis it came from, its
    joint ``score``, its ``margin`` over the best candidate of another cluster (``runner_up`` (4, 4), NaN where
    there is none), and the ``loop_residual_deg``: the largest rotation residual (deg) of the pose graph's edges
    at this view (NaN with two views: no pose graph)."""

    pose: np.ndarray
    source: Source
    score: float
    margin: float
    runner_up: np.ndarray
    loop_residual_deg: float


def relative(rankings: Mapping[tuple[int, int], PairRanking], first: int, second: int) -> list[ScoredHypothesis]:
    """The ranked hypotheses of view ``second`` in view ``first``'s frame (a pair is ranked once, lower index as
    target: the reverse pair's transforms are inverted)."""
    if (first, second) in rankings:
        return rankings[(first, second)].clusters
    return [ScoredHypothesis(np.linalg.inv(h.transform), h.source, h.score, h.object_score)
            for h in rankings[(second, first)].clusters]


def joint_score(evidence: Sequence[ViewEvidence | None], poses: Mapping[int, np.ndarray], view: int,
                pose: np.ndarray, tolerance_floor: float) -> float:
    """The verifier's scores of ``view`` at ``pose`` (4, 4, anchor frame) against every placed view, averaged."""
    scores = [verify(evidence[other], evidence[view], np.linalg.inv(placed) @ pose, tolerance_floor).score
              for other, placed in poses.items() if other != view]
    return float(np.mean(scores))


def choose_poses(evidence: Sequence[ViewEvidence | None], rankings: Mapping[tuple[int, int], PairRanking],
                 extent: float, tolerance_floor: float) -> dict[int, ChosenPose]:
    """Every view with evidence (index > 0) placed in the anchor's frame from the pairs' ``rankings`` (keyed by
    (target, source) view indices, target < source)."""
    placeable = [k for k in range(1, len(evidence)) if evidence[k] is not None and (0, k) in rankings]
    order = sorted(placeable, key=lambda k: -rankings[(0, k)].margin)  # the surest views first
    poses: dict[int, np.ndarray] = {0: np.eye(4)}
    chosen: dict[int, ChosenPose] = {}
    for _ in range(ROUNDS if len(placeable) > 1 else 1):
        for k in order:
            if set(poses) - {k} == {0}:  # only the anchor placed: the pair's own scores are the joint ones
                ranked = rankings[(0, k)].clusters
            else:
                candidates = list(rankings[(0, k)].clusters)
                for j, placed in poses.items():
                    if j not in (0, k) and ((j, k) in rankings or (k, j) in rankings):
                        candidates += [ScoredHypothesis(placed @ h.transform, h.source, h.score, h.object_score)
                                       for h in relative(rankings, j, k)]
                priors = rankings[(0, k)].priors
                ranked = clusters_of([ScoredHypothesis(
                    c.transform, c.source, priors.of(c.transform, extent) + joint_score(
                        evidence, poses, k, c.transform, tolerance_floor), c.object_score) for c in candidates], extent)
            best = ranked[0]
            margin = best.score - (ranked[1].score if len(ranked) > 1 else 0.0)
            runner_up = ranked[1].transform if len(ranked) > 1 else np.full((4, 4), np.nan)
            poses[k] = best.transform
            chosen[k] = ChosenPose(best.transform, best.source, best.score, margin, runner_up, math.nan)
    if len(chosen) < 2:
        return chosen
    fitted, loops = optimise(poses, agreeing_edges(rankings, poses), extent)
    return {k: dataclasses.replace(c, pose=fitted[k], loop_residual_deg=loops[k]) for k, c in chosen.items()}
