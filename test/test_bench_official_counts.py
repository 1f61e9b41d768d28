"""bench/official_counts.py: the official ID-Pose work per estimate, against hand counts and our solver's counters.

Reduced: the solver comparison uses a small schedule (4 x 2 candidates, probe batch 2, 2 adjust
steps, 2 kept, 5 refinement steps) and a coarse render oracle (30 deg grid, 8 px latents).
"""
import numpy as np
import pytest
import torch

from bench.official_counts import OfficialSchedule, official_counts
from idpose_core.solver import SolverConfig, estimate_poses
from idpose_core.synthetic.render_oracle import RenderOracle
from idpose_core.synthetic.scenes import oracle_objects, random_camera_spheres


def test_two_views_with_the_official_defaults():
    # 40 candidates probed both ways + 20 adjusted re-probed both ways; 20 x 10 adjust + 600 refine steps
    counts = official_counts(2)
    assert (counts["probes"], counts["steps"]) == (120, 800)
    assert counts["triangular_probes"] == 0
    assert (counts["forward_samples"], counts["backward_samples"]) == (120 * 16 + 800, 800)


def test_three_views_add_triangular_probes():
    # per view 80 + 40 probes; one pair of non-anchor views: 5 x 5 combinations both ways = 50
    counts = official_counts(3)
    assert (counts["exploration_probes"], counts["reprobes"], counts["triangular_probes"]) == (160, 80, 50)
    assert (counts["adjust_steps"], counts["refine_steps"]) == (400, 1200)


def test_without_adjustment_the_best_five_grid_candidates_are_kept():
    counts = official_counts(3, OfficialSchedule(adjust_steps=0))
    assert (counts["reprobes"], counts["adjust_steps"], counts["triangular_probes"]) == (0, 0, 50)


def test_fewer_than_two_views_is_refused():
    with pytest.raises(ValueError, match="views"):
        official_counts(1)


def test_our_solver_does_the_official_work_plus_scoring_and_runner_up():
    schedule = OfficialSchedule(azimuth_candidates=4, polar_candidates=2, probe_batch=2, adjust_steps=2,
                                keep_top=2, refine_steps_per_view=5)
    config = SolverConfig(azimuth_candidates=4, polar_candidates_deg=(-60.0, 60.0), probe_batch=2, adjust_steps=2,
                          keep_top=2, refine_steps_per_view=5, runner_up_steps=3, adjust_lr=0.2, refine_lr=0.02)
    views = random_camera_spheres(np.random.default_rng(0), 3)
    oracle = RenderOracle(oracle_objects(1)[0], views, step_deg=30.0, latent_size=8, render_size=16)
    result = estimate_poses(oracle, torch.zeros(3, 3, 16, 16), config)
    official = official_counts(3, schedule)
    runner_up = 2 * config.runner_up_steps  # one sample per step, per non-anchor view
    scoring = 2 * 2 * 2 * config.probe_batch  # answer and runner-up per view, both directions
    assert result.backward_samples == official["backward_samples"] + runner_up
    assert result.forward_samples == official["forward_samples"] + runner_up + scoring
