"""Candidate selection: pairwise best, or triangular consistency across views for the "full" variant."""
from __future__ import annotations

import torch

from idpose_core.solver.context import SolverContext
from idpose_core.solver.exploration import ViewCandidates
from idpose_core.spherical import compose, invert

TRIANGLE_CAP = 3.0  # a pair's triangle term never exceeds 3x the candidate's own pairwise error (official)


def triangular_scores(ctx: SolverContext, candidates: list[ViewCandidates]) -> list[torch.Tensor]:
    """Per view i, a score (k_i,) per candidate u: sum over other views j of its best triangle error.

    Triangle error ``l_i0j = l0i(p_iu) + l0j(p_jv) + lij(p'_iu + p_jv)``, minimised over v and capped
    at ``TRIANGLE_CAP * l0i(p_iu)``; every (i, j, u, v) probe goes through one batched evaluation.
    """
    count = len(candidates)
    pairs = [(i, j) for i in range(count) for j in range(i + 1, count)]
    refs, tgts, poses, shapes = [], [], [], []
    for i, j in pairs:
        first, second = candidates[i].poses, candidates[j].poses
        between = compose(invert(first)[:, None], second[None, :])  # (k_i, k_j, 3): view i -> view j
        refs.append(torch.full((between.shape[0] * between.shape[1],), i + 1))
        tgts.append(torch.full_like(refs[-1], j + 1))
        poses.append(between.reshape(-1, 3))
        shapes.append(between.shape[:2])
    ctx.begin_stage("selection", sum(len(r) for r in refs) * 2 * ctx.config.probe_batch)
    scores = [torch.zeros(len(c.errors)) for c in candidates]
    if not pairs:
        return scores
    errors = ctx.pairwise_errors(torch.cat(refs), torch.cat(tgts), torch.cat(poses))
    for (i, j), shape, chunk in zip(pairs, shapes, torch.split(errors, [a * b for a, b in shapes])):
        first, second = candidates[i].errors, candidates[j].errors
        triangle = first[:, None] + second[None, :] + chunk.view(shape)
        scores[i] += torch.minimum(triangle.min(dim=1).values, TRIANGLE_CAP * first)
        scores[j] += torch.minimum(triangle.min(dim=0).values, TRIANGLE_CAP * second)
    return scores


def select(ctx: SolverContext, candidates: list[ViewCandidates]) -> torch.Tensor:
    """Chosen start pose per view (N-1, 3): lowest pairwise error, or lowest triangular score ("full", N > 2)."""
    if ctx.config.variant == "full" and len(candidates) > 1:
        choice = [int(torch.argmin(score)) for score in triangular_scores(ctx, candidates)]
    else:
        choice = [0] * len(candidates)  # candidates come sorted by pairwise error
    return torch.stack([c.poses[k] for c, k in zip(candidates, choice)])
