"""Exploration: probe a grid of pose candidates per (anchor, view) pair, adjust the better half, keep the best."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from idpose_core.solver.config import SolverConfig
from idpose_core.solver.context import SolverContext
from idpose_core.spherical import invert


@dataclass(frozen=True)
class ViewCandidates:
    """Exploration outcome for the pair (anchor, view i), all poses from the anchor to view i.

    ``poses`` (k, 3) / ``errors`` (k,): the kept candidates, lowest probe error first.
    ``pool_poses`` (M, 3) / ``pool_errors`` (M,): every candidate probed (grid and adjusted), all
    under the same fixed probe noise, so their errors compare with each other and with the final score.
    """

    poses: torch.Tensor
    errors: torch.Tensor
    pool_poses: torch.Tensor
    pool_errors: torch.Tensor


def candidate_grid(config: SolverConfig) -> torch.Tensor:
    """Azimuths uniform in [0, 2pi) x polar candidates, relative radius 0; (m * P, 3), azimuth-major."""
    azimuths = np.arange(config.azimuth_candidates) * (2.0 * np.pi / config.azimuth_candidates)
    polars = config.polar_candidates()
    grid = [(polar, azimuth, 0.0) for azimuth in azimuths for polar in polars]
    return torch.tensor(grid, dtype=torch.float32)


def adjust(ctx: SolverContext, starts: torch.Tensor, views: torch.Tensor) -> torch.Tensor:
    """``adjust_steps`` SGD steps at ``adjust_lr`` on each start pose (K, 3) towards its view (K,).

    Candidates are independent, so all of them share each step's batch; steps alternate between
    the forward direction ``l(p; x0, xi)`` and the reverse ``l(p'; xi, x0)``.
    """
    pose = starts.to(ctx.device).clone().requires_grad_(True)
    optimiser = torch.optim.SGD([pose], lr=ctx.config.adjust_lr)
    anchor = torch.zeros_like(views)
    for step in range(ctx.config.adjust_steps):
        forward = step % 2 == 0
        optimiser.zero_grad()
        ctx.gradient_step(anchor if forward else views, views if forward else anchor,
                          pose if forward else invert(pose))
        optimiser.step()
    return pose.detach().cpu()


def explore(ctx: SolverContext, view_count: int) -> list[ViewCandidates]:
    """Candidates for every view 1..N-1 relative to the anchor, each view's work batched with the others'."""
    config = ctx.config
    grid = candidate_grid(config)
    pairs, size = view_count - 1, len(grid)
    half = max(size // 2, 1) if config.adjust_steps > 0 else 0
    probe = 2 * config.probe_batch
    ctx.begin_stage("exploration", pairs * (size * probe + half * (config.adjust_steps + probe)))

    targets = torch.arange(1, view_count).repeat_interleave(size)
    errors = ctx.pairwise_errors(torch.zeros_like(targets), targets, grid.repeat(pairs, 1)).view(pairs, size)
    order = torch.argsort(errors, dim=1, stable=True)
    pool_poses, pool_errors = grid.expand(pairs, size, 3), errors
    if half:
        starts = grid[order[:, :half]].reshape(-1, 3)
        targets = torch.arange(1, view_count).repeat_interleave(half)
        adjusted = adjust(ctx, starts, targets)
        adjusted_errors = ctx.pairwise_errors(torch.zeros_like(targets), targets, adjusted).view(pairs, half)
        pool_poses = torch.cat([pool_poses, adjusted.view(pairs, half, 3)], dim=1)
        pool_errors = torch.cat([errors, adjusted_errors], dim=1)
        choice_poses, choice_errors = adjusted.view(pairs, half, 3), adjusted_errors
    else:
        choice_poses, choice_errors = grid.expand(pairs, size, 3), errors

    result = []
    for view in range(pairs):
        best = torch.argsort(choice_errors[view], stable=True)[: config.keep_top]
        result.append(ViewCandidates(choice_poses[view, best], choice_errors[view, best],
                                     pool_poses[view], pool_errors[view]))
    return result
