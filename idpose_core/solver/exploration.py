"""Exploration: probe a grid of pose candidates per (anchor, view) pair, narrow it on the azimuth, adjust the better
ones, keep the best."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from idpose_core.solver.config import SolverConfig
from idpose_core.solver.context import SolverContext
from idpose_core.solver.refinement import pose_distance
from idpose_core.spherical import invert

NEW_POSE_RAD = 1e-4  # a narrowed candidate this close to one already probed is not probed again


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


def candidate_grid(config: SolverConfig, known_polar: float = math.nan) -> torch.Tensor:
    """Azimuths uniform in [0, 2pi) x polar candidates (the one ``known_polar`` when finite), relative
    radius 0; (m * P, 3), azimuth-major."""
    azimuths = np.arange(config.azimuth_candidates) * (2.0 * np.pi / config.azimuth_candidates)
    polars = [known_polar] if math.isfinite(known_polar) else config.polar_candidates()
    grid = [(polar, azimuth, 0.0) for azimuth in azimuths for polar in polars]
    return torch.tensor(grid, dtype=torch.float32)


def narrowed(poses: torch.Tensor, errors: torch.Tensor, keep: int, step: float) -> torch.Tensor:
    """The ``keep`` lowest-error poses (k, 3) of a pool, each shifted by -``step`` and +``step`` in azimuth (radians),
    less those already in the pool; (m, 3), m <= 2 * keep."""
    best = poses[torch.argsort(errors, stable=True)[:keep]]
    shifted = torch.cat([best + torch.tensor([0.0, sign * step, 0.0]) for sign in (-1.0, 1.0)])
    shifted[:, 1] = torch.remainder(shifted[:, 1], 2.0 * math.pi)
    fresh: list[torch.Tensor] = []
    for pose in shifted:
        probed = torch.cat([poses, *(kept[None] for kept in fresh)])
        if not bool((pose_distance(probed, pose) < NEW_POSE_RAD).any()):
            fresh.append(pose)
    return torch.stack(fresh) if fresh else poses[:0]


def narrow(ctx: SolverContext, views: torch.Tensor, poses: list[torch.Tensor], errors: list[torch.Tensor]
           ) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
    """Coarse to fine on the azimuth (``azimuth_refinements`` levels): each level probes every view's best
    ``keep_top`` candidates at half the last spacing on either side, in one batch over all views; the grown
    pools (poses, errors) per view, every probe under the same fixed noise."""
    spacing = 2.0 * math.pi / ctx.config.azimuth_candidates
    for level in range(1, ctx.config.azimuth_refinements + 1):
        new = [narrowed(pool, error, ctx.config.keep_top, spacing / 2 ** level) for pool, error in zip(poses, errors)]
        targets = views.repeat_interleave(torch.tensor([len(n) for n in new]))
        new_errors = torch.split(ctx.pairwise_errors(torch.zeros_like(targets), targets, torch.cat(new)),
                                 [len(n) for n in new])
        poses = [torch.cat([pool, more]) for pool, more in zip(poses, new)]
        errors = [torch.cat([error, more]) for error, more in zip(errors, new_errors)]
    return poses, errors


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
        ctx.hold_known_polar(pose, views)
        optimiser.step()
    return pose.detach().cpu()


def explore(ctx: SolverContext, view_count: int) -> list[ViewCandidates]:
    """Candidates for every view 1..N-1 relative to the anchor, each view's work batched with the others'.

    A view whose relative polar angle is known (``ctx.known_polar``) searches azimuth only.
    """
    config = ctx.config
    grids = [candidate_grid(config, float(polar)) for polar in ctx.known_polar[:view_count - 1]]
    sizes = [len(grid) for grid in grids]
    adjusted_count = (lambda size: min(config.adjust_top, size)) if config.adjust_top else (
        lambda size: max(size // 2, 1))
    halves = [adjusted_count(size) if config.adjust_steps > 0 else 0 for size in sizes]
    probe = 2 * config.probe_batch
    narrowing = 2 * sum(min(config.keep_top, size) for size in sizes) * config.azimuth_refinements
    ctx.begin_stage("exploration", narrowing * probe + sum(size * probe + half * (config.adjust_steps + probe)
                                                           for size, half in zip(sizes, halves)))

    views = torch.arange(1, view_count)
    targets = views.repeat_interleave(torch.tensor(sizes))
    errors = torch.split(ctx.pairwise_errors(torch.zeros_like(targets), targets, torch.cat(grids)), sizes)
    pool_poses, pool_errors = narrow(ctx, views, list(grids), list(errors))
    choice_poses, choice_errors = list(pool_poses), list(pool_errors)
    if any(halves):
        starts = torch.cat([pool[torch.argsort(error, stable=True)[:half]]
                            for pool, error, half in zip(pool_poses, pool_errors, halves)])
        targets = views.repeat_interleave(torch.tensor(halves))
        adjusted = adjust(ctx, starts, targets)
        adjusted_errors = ctx.pairwise_errors(torch.zeros_like(targets), targets, adjusted)
        choice_poses, choice_errors = list(torch.split(adjusted, halves)), list(torch.split(adjusted_errors, halves))
        pool_poses = [torch.cat([pool, more]) for pool, more in zip(pool_poses, choice_poses)]
        pool_errors = [torch.cat([error, more]) for error, more in zip(pool_errors, choice_errors)]

    result = []
    for poses, errors, all_poses, all_errors in zip(choice_poses, choice_errors, pool_poses, pool_errors):
        best = torch.argsort(errors, stable=True)[: config.keep_top]
        result.append(ViewCandidates(poses[best], errors[best], all_poses, all_errors))
    return result
