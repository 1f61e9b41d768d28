"""Final scores, runner-ups and the ambiguity flag per view.

Rule: the runner-up of view i starts as the lowest-error candidate probed during exploration whose
pose differs from the answer by more than ``ambiguity_deg`` (in polar or in circular azimuth); it is
then polished with ``runner_up_steps`` pairwise refinement steps per view, so that it sits at the
bottom of its own basin as the answer does (with ``runner_up_gate``, only when some view's runner-up
probed close to its pool's best). View i is *ambiguous* when the polished runner-up is
still far from the answer and ``runner_up_score - score <= ambiguity_margin * (worst_probe - score)``:
a distinct minimum almost as deep as the answer's, measured against the spread of errors over the
candidate grid. The view's *confidence* is that same margin, ``(runner_up_score - score) / spread``
clipped to [0, 1] (1 when no far minimum survives the polish): ambiguous views are exactly those far
minima whose confidence is at most ``ambiguity_margin``. All errors are taken under the same fixed probe
noise, so they compare directly; mirror or rotationally symmetric objects give such near-equal far minima.
"""
from __future__ import annotations

import math

import torch

from idpose_core.solver.config import SolverConfig
from idpose_core.solver.context import SolverContext
from idpose_core.solver.exploration import ViewCandidates
from idpose_core.solver.refinement import pose_distance, refine


def runner_up_starts(poses: torch.Tensor, candidates: list[ViewCandidates], limit: float
                     ) -> tuple[torch.Tensor, torch.Tensor]:
    """Per view the best pool candidate farther than ``limit`` from its answer (N-1, 3) and its pool error
    (N-1,); NaN where there is none."""
    starts = torch.full_like(poses, math.nan)
    errors = torch.full((len(poses),), math.nan)
    for view, (pose, found) in enumerate(zip(poses, candidates)):
        far = pose_distance(found.pool_poses, pose) > limit
        if far.any():
            far_errors = torch.where(far, found.pool_errors, torch.full_like(found.pool_errors, math.inf))
            best = int(torch.argmin(far_errors))
            starts[view], errors[view] = found.pool_poses[best], found.pool_errors[best]
    return starts, errors


def worth_polishing(config: SolverConfig, start_errors: torch.Tensor, candidates: list[ViewCandidates]) -> bool:
    """Whether to polish the runner-ups: some view has one, and (with ``runner_up_gate``) its error lies
    within that share of the pool's spread of the pool's best error."""
    found = ~torch.isnan(start_errors)
    if config.runner_up_steps == 0 or not found.any():
        return False
    if config.runner_up_gate is None:
        return True
    best = torch.stack([c.pool_errors.min() for c in candidates])
    spread = torch.stack([c.pool_errors.max() for c in candidates]) - best
    return bool((found & (start_errors - best <= config.runner_up_gate * spread)).any())


def score(ctx: SolverContext, poses: torch.Tensor, candidates: list[ViewCandidates]
          ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Scores (N-1,), runner-up poses (N-1, 3), runner-up scores (N-1,), ambiguity flags (N-1,) and
    confidences (N-1,) in [0, 1]. Runner-ups left unpolished keep their pool error (the same probe noise)."""
    config = ctx.config
    limit = math.radians(config.ambiguity_deg)
    starts, start_errors = runner_up_starts(poses, candidates, limit)
    found = ~torch.isnan(starts[:, 0])
    polish = worth_polishing(config, start_errors, candidates)
    # views without a far candidate polish their own answer (refinement runs over all views at once)
    runners = refine(ctx, torch.where(found[:, None], starts, poses), "naive",
                     config.runner_up_steps if polish else 0, stage="runner-up")

    count = len(poses)
    probed = torch.cat([poses, runners]) if polish else poses
    ctx.begin_stage("scoring", len(probed) * 2 * config.probe_batch)
    views = torch.arange(1, count + 1).repeat(len(probed) // count)
    errors = ctx.pairwise_errors(torch.zeros_like(views), views, probed)
    scores = errors[:count]
    runners[~found] = math.nan
    runner_scores = torch.where(found, errors[count:] if polish else start_errors, torch.full((count,), math.nan))
    spread = torch.stack([c.pool_errors.max() for c in candidates]) - scores
    still_far = pose_distance(runners, poses) > limit
    margin = runner_scores - scores
    close = margin <= config.ambiguity_margin * spread
    rival = found & still_far
    confidence = torch.where(rival, (margin / spread.clamp_min(1e-12)).clamp(0.0, 1.0), torch.ones_like(scores))
    return scores, runners, runner_scores, rival & close, confidence
