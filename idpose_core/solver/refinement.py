"""Refinement: SGD on all relative poses over a schedule of view pairs, answer = mean of the last iterates."""
from __future__ import annotations

import math

import torch

from idpose_core.solver.context import SolverContext
from idpose_core.spherical import compose, invert


def pair_schedule(view_count: int, variant: str) -> list[tuple[int, int]]:
    """Ordered (reference, target) pairs cycled by refinement.

    "naive": anchor to each view, then each view to the anchor; "tr"/"full": every ordered pair,
    each followed by its reverse, so consecutive steps alternate directions.
    """
    if variant == "naive":
        return [(0, i) for i in range(1, view_count)] + [(i, 0) for i in range(1, view_count)]
    return [pair for i in range(view_count) for j in range(i + 1, view_count) for pair in ((i, j), (j, i))]


def circular_mean(angles: torch.Tensor, dim: int = 0) -> torch.Tensor:
    """Mean direction of angles (radians) along ``dim``, in [0, 2pi)."""
    mean = torch.atan2(torch.sin(angles).mean(dim=dim), torch.cos(angles).mean(dim=dim))
    return torch.remainder(mean, 2.0 * math.pi)


def mean_pose(iterates: torch.Tensor) -> torch.Tensor:
    """Mean of pose iterates (T, 3): arithmetic for polar and radius, circular for azimuth; (3,)."""
    mean = iterates.mean(dim=0)
    return torch.stack([mean[0], circular_mean(iterates[:, 1]), mean[2]])


def pose_distance(first: torch.Tensor, second: torch.Tensor) -> torch.Tensor:
    """Largest of |d polar| and circular |d azimuth| between poses (..., 3), radians."""
    polar = (first[..., 0] - second[..., 0]).abs()
    azimuth = torch.remainder(first[..., 1] - second[..., 1], 2.0 * math.pi)
    return torch.maximum(polar, torch.minimum(azimuth, 2.0 * math.pi - azimuth))


def settled(history: list[list[torch.Tensor]], steps: int, bound: float) -> bool:
    """Whether every view has moved at most ``bound`` radians (``pose_distance``) over its last ``steps`` iterates."""
    return all(len(h) > steps and float(pose_distance(h[-1], h[-1 - steps])) <= bound for h in history)


def refine(ctx: SolverContext, start: torch.Tensor, variant: str, steps_per_view: int,
           stage: str = "refinement") -> torch.Tensor:
    """Refined poses (N-1, 3) from start poses (N-1, 3), anchor to views 1..N-1.

    Runs ``steps_per_view * (N-1)`` steps over ``pair_schedule(N, variant)``. Step s takes pair
    (i, j) = schedule[s mod len]: i = 0 updates p_j with ``l(p_j; x0, xj)``; j = 0 updates p_i with
    ``l(p'_i; xi, x0)``; otherwise a seeded coin holds one of p_i, p_j fixed and the other is updated
    with ``l(p'_i + p_j; xi, xj)``. Each step: one sample, fresh noise and t, one SGD step at
    ``refine_lr``. A view's answer is the mean of its last ``average_last`` iterates. With
    ``refine_stop_steps`` k > 0, it stops once no view moved more than ``refine_stop_deg`` over its last k
    iterates.
    """
    config = ctx.config
    count = len(start) + 1
    steps = steps_per_view * (count - 1)
    ctx.begin_stage(stage, steps)
    if steps == 0:
        return start.clone()
    schedule = pair_schedule(count, variant)
    poses = start.to(ctx.device).clone().requires_grad_(True)
    optimiser = torch.optim.SGD([poses], lr=config.refine_lr)
    history: list[list[torch.Tensor]] = [[] for _ in range(count - 1)]
    for step in range(steps):
        ref, tgt = schedule[step % len(schedule)]
        if ref == 0:
            updated, pose = tgt, poses[tgt - 1]
        elif tgt == 0:
            updated, pose = ref, invert(poses[ref - 1])
        else:
            hold_ref = bool(ctx.uniform(1) < 0.5)
            updated = tgt if hold_ref else ref
            first = poses[ref - 1].detach() if hold_ref else poses[ref - 1]
            second = poses[tgt - 1] if hold_ref else poses[tgt - 1].detach()
            pose = compose(invert(first), second)
        optimiser.zero_grad()
        ctx.gradient_step(torch.tensor([ref]), torch.tensor([tgt]), pose[None])
        ctx.hold_known_polar(poses, torch.arange(1, count))
        optimiser.step()
        history[updated - 1].append(poses[updated - 1].detach().cpu().clone())
        if config.refine_stop_steps and settled(history, config.refine_stop_steps,
                                                math.radians(config.refine_stop_deg)):
            break
    return torch.stack([mean_pose(torch.stack(h[-config.average_last:])) if h else start[k].cpu()
                        for k, h in enumerate(history)])
