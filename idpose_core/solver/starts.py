"""iFusion's pose search: Adam from a few start azimuths per view, both directions per step, the timestep annealed.

Each view is searched against the anchor alone (as iFusion does it); all starts of all views share
each step's batch. A start's loss per step is the mean of ``l(p; x0, xi)`` and ``l(p'; xi, x0)`` at one
timestep, and the start whose loss summed over its steps is smallest wins. The relative radius is
searched through ``start_radius_range * sin(u)`` so it stays bounded. Both directions of all starts
of one view draw the same noise at a step (common random numbers: the summed losses of a view's
starts compare on equal draws).
"""
from __future__ import annotations

import math

import torch

from idpose_core.solver.config import SolverConfig
from idpose_core.solver.context import SolverContext
from idpose_core.solver.exploration import ViewCandidates
from idpose_core.spherical import invert


def start_poses(config: SolverConfig, known_polar: float = math.nan) -> torch.Tensor:
    """The search's start poses (S, 3): each start azimuth at relative polar 0 (or the known one), radius 0."""
    polar = known_polar if math.isfinite(known_polar) else 0.0
    return torch.tensor([(polar, math.radians(azimuth), 0.0) for azimuth in config.start_azimuths_deg],
                        dtype=torch.float32)


def annealed_timestep(config: SolverConfig, step: int, train_steps: int) -> int:
    """Step ``step``'s timestep: linear from ``start_t_range[0]`` to ``[1]`` over ``start_steps``, in [0, T - 1]."""
    first, last = config.start_t_range
    fraction = first + (last - first) * step / config.start_steps
    return min(max(int(round(fraction * train_steps)), 0), train_steps - 1)


def bounded_radius(raw: torch.Tensor, config: SolverConfig) -> torch.Tensor:
    """Poses (K, 3) from the searched variables (K, 3): the third one u gives the radius ``range * sin(u)``."""
    return torch.stack([raw[:, 0], raw[:, 1], config.start_radius_range * torch.sin(raw[:, 2])], dim=1)


def search_starts(ctx: SolverContext, view_count: int) -> list[ViewCandidates]:
    """Candidates per view 1..N-1: every start's final pose, ordered by summed loss (the winner first).

    Adam at ``start_lr``; the learning rate drops by ``start_lr_factor`` when the summed loss has not
    improved for ``start_lr_patience`` steps (``ReduceLROnPlateau`` on the running sum, as iFusion feeds
    it: a sum of positive losses never improves, so it is a drop every patience + 1 steps, the same for
    every start). The final poses are then probed once under the fixed probe noise, so that scoring
    compares them with the answer as it does grid candidates.
    """
    config = ctx.config
    views = torch.arange(1, view_count)
    starts = torch.cat([start_poses(config, float(polar)) for polar in ctx.known_polar[:view_count - 1]])
    per_view = len(config.start_azimuths_deg)
    rows = views.repeat_interleave(per_view)  # (K,) the view each start searches
    count = len(rows)
    ctx.begin_stage("exploration", count * 2 * (config.start_steps + config.probe_batch))

    raw = starts.to(ctx.device).clone().requires_grad_(True)  # radius 0 <=> u = 0
    optimiser = torch.optim.Adam([raw], lr=config.start_lr)
    scheduler = torch.optim.lr_scheduler.ReduceLROnPlateau(
        optimiser, mode="min", factor=config.start_lr_factor, patience=config.start_lr_patience)
    anchor = torch.zeros_like(rows)
    ref, tgt = torch.cat([anchor, rows]), torch.cat([rows, anchor])
    summed = torch.zeros(count)
    for step in range(config.start_steps):
        t = torch.full((2 * count,), annealed_timestep(config, step, ctx.predictor.num_train_timesteps))
        noise = ctx.draw_noise(2 * (view_count - 1)).view(2, view_count - 1, *ctx.views.noise_shape)
        optimiser.zero_grad()
        pose = bounded_radius(raw, config)
        errors = ctx.gradient_step(ref, tgt, torch.cat([pose, invert(pose)]), t,
                                   torch.cat([noise[0, rows - 1], noise[1, rows - 1]]))
        ctx.hold_known_polar(raw, rows)
        optimiser.step()
        summed += errors.view(2, count).mean(dim=0).float().cpu()
        scheduler.step(float(summed.sum()))

    final = bounded_radius(raw.detach(), config).cpu()
    probed = ctx.pairwise_errors(anchor, rows, final)
    result = []
    for poses, errors, losses in zip(final.split(per_view), probed.split(per_view), summed.split(per_view)):
        order = torch.argsort(losses, stable=True)[: config.keep_top]
        result.append(ViewCandidates(poses[order], errors[order], poses, errors))
    return result
