"""What the official ID-Pose implementation evaluates per estimate, derived from its published algorithm.

Read from the public repository xt4d/id-pose (``src/pose_estimation.py: estimate_poses``,
``src/pose_funcs.py: probe_pose, pairwise_loss, noise_loss, find_optimal_poses``) with the defaults
of its ``test_pose_estimation.py`` (``probe_bsz`` 16, ``adjust_iters`` 10, ``optm_iters`` 600,
triangular exploration and refinement); elevation estimation (an optional extra model) is left out.

- A *probe* is one ``noise_loss`` call: one pose candidate, one direction, a batch of ``probe_batch``
  noises, forward only. ``pairwise_loss`` is two probes (the pose and its inverse, images swapped).
- A *step* is one ``find_optimal_poses`` iteration with ``bsz`` 1: one sample, forward and backward.

Per view i = 1..n-1 (anchor 0): ``probe_pose`` probes every candidate of the grid (8 azimuths x 5
polars from -120 to 120 deg = 40) pairwise; the first half (20) is adjusted with ``adjust_iters``
steps each, then re-probed pairwise; the best ``keep_top`` (5) are kept. For n > 2, triangular
exploration probes, for every pair 1 <= i < j <= n-1, all 5 x 5 candidate combinations pairwise.
Refinement runs ``(n-1) x optm_iters`` steps.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class OfficialSchedule:
    """The official defaults that set the amount of work (``test_pose_estimation.py`` arguments)."""

    azimuth_candidates: int = 8
    polar_candidates: int = 5
    probe_batch: int = 16
    adjust_steps: int = 10
    keep_top: int = 5
    refine_steps_per_view: int = 600


def official_counts(views: int, schedule: OfficialSchedule = OfficialSchedule()) -> dict[str, int]:
    """Probes, steps and predictor samples of one official estimate of ``views`` (>= 2) views.

    Returns ``probes`` (one direction x ``probe_batch`` noises each), ``steps`` (one sample forward and
    backward each), their split by stage, ``forward_samples`` (every sample evaluated, as the
    solver counts them) and ``backward_samples`` (samples differentiated).
    """
    if views < 2:
        raise ValueError(f"views must be >= 2 (an anchor and one more), got {views}")
    pairs = views - 1
    candidates = schedule.azimuth_candidates * schedule.polar_candidates
    adjusted = candidates // 2 if schedule.adjust_steps > 0 else 0
    kept = min(schedule.keep_top, adjusted if adjusted else candidates)
    view_pairs = pairs * (pairs - 1) // 2  # triangular exploration: pairs of non-anchor views
    probes = {
        "exploration_probes": pairs * 2 * candidates,
        "reprobes": pairs * 2 * adjusted,
        "triangular_probes": view_pairs * kept * kept * 2,
    }
    steps = {
        "adjust_steps": pairs * adjusted * schedule.adjust_steps,
        "refine_steps": pairs * schedule.refine_steps_per_view,
    }
    total_probes, total_steps = sum(probes.values()), sum(steps.values())
    return {
        **probes, **steps,
        "probes": total_probes,
        "steps": total_steps,
        "forward_samples": total_probes * schedule.probe_batch + total_steps,
        "backward_samples": total_steps,
    }

