"""Final scores, runner-ups and the ambiguity flag per view.

Rule: the runner-up of view i is the lowest-error candidate probed during exploration whose pose
differs from the answer by more than ``ambiguity_deg`` (in polar or in circular azimuth). View i is
*ambiguous* when ``runner_up_score - score <= ambiguity_margin * (worst_probe - score)``: the far
candidate is almost as good as the answer, measured against the spread of errors over the whole
candidate grid. All errors are taken under the same fixed probe noise, so they compare directly;
mirror or rotationally symmetric objects give such near-equal far minima.
"""
from __future__ import annotations

import math

import torch

from idpose_core.solver.context import SolverContext
from idpose_core.solver.exploration import ViewCandidates


def pose_distance(first: torch.Tensor, second: torch.Tensor) -> torch.Tensor:
    """Largest of |d polar| and circular |d azimuth| between poses (..., 3), radians."""
    polar = (first[..., 0] - second[..., 0]).abs()
    azimuth = torch.remainder(first[..., 1] - second[..., 1], 2.0 * math.pi)
    return torch.maximum(polar, torch.minimum(azimuth, 2.0 * math.pi - azimuth))


def score(ctx: SolverContext, poses: torch.Tensor, candidates: list[ViewCandidates]
          ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Scores (N-1,), runner-up poses (N-1, 3), runner-up scores (N-1,) and ambiguity flags (N-1,)."""
    count = len(poses)
    ctx.begin_stage("scoring", count * 2 * ctx.config.probe_batch)
    views = torch.arange(1, count + 1)
    scores = ctx.pairwise_errors(torch.zeros_like(views), views, poses)
    runner_poses = torch.full((count, 3), math.nan)
    runner_scores = torch.full((count,), math.nan)
    ambiguous = torch.zeros(count, dtype=torch.bool)
    limit = math.radians(ctx.config.ambiguity_deg)
    for view, (pose, found) in enumerate(zip(poses, candidates)):
        far = pose_distance(found.pool_poses, pose) > limit
        if not far.any():
            continue
        errors = torch.where(far, found.pool_errors, torch.full_like(found.pool_errors, math.inf))
        best = int(torch.argmin(errors))
        runner_poses[view], runner_scores[view] = found.pool_poses[best], errors[best]
        spread = float(found.pool_errors.max()) - float(scores[view])
        ambiguous[view] = bool(errors[best] - scores[view] <= ctx.config.ambiguity_margin * spread)
    return scores, runner_poses, runner_scores, ambiguous
