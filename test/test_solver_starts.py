"""The iFusion search (``search="starts"``) and the cost levers of the grid search, on render-oracle scenes.

Reduced: 10 deg oracle grid at 16 px for the mechanics; 20 start steps instead of iFusion's 100 there.
The accuracy test runs the ``ifusion`` preset as it is (4 starts x 100 steps) on 64 px held-out scenes.
"""
import math

import numpy as np
import torch
from test_solver_estimate import CountingPredictor, images

from idpose_core.cameras import spherical_to_c2w
from idpose_core.metrics import pair_errors
from idpose_core.solver import SolverConfig, estimate_poses
from idpose_core.solver.config import PRESETS
from idpose_core.solver.starts import annealed_timestep
from idpose_core.synthetic.render_oracle import ORACLE_SOLVER_SETTINGS, RenderOracle
from idpose_core.synthetic.scenes import SceneRenderer, oracle_objects, random_camera_spheres

STARTS = SolverConfig.preset("ifusion", start_steps=20)


def scene(count: int, seed: int = 7) -> CountingPredictor:
    views = random_camera_spheres(np.random.default_rng(seed), count)
    return CountingPredictor(RenderOracle(oracle_objects()[2], views, step_deg=10.0, latent_size=16, render_size=32))


def test_each_step_batches_both_directions_of_every_start_and_the_counters_add_up():
    predictor = scene(3)
    result = estimate_poses(predictor, images(3), STARTS)
    starts = len(STARTS.start_azimuths_deg) * 2  # two non-anchor views
    assert result.stage_samples["exploration"][1] == STARTS.start_steps * 2 * starts
    assert result.backward_samples == STARTS.start_steps * 2 * starts  # no refinement, no runner-up polish
    # each step's 2 x 8 samples go through in chunks of grad_batch
    assert [size for size, grad in predictor.calls if grad] == [STARTS.grad_batch] * (2 * STARTS.start_steps)
    assert result.forward_samples == sum(size for size, _ in predictor.calls)
    # the final poses are probed once, then the answers are scored: unpolished runner-ups keep their probe
    probes = result.forward_samples - result.backward_samples
    assert probes == (starts + 2) * 2 * STARTS.probe_batch


def test_the_timestep_is_annealed_as_ifusion_anneals_it():
    config = SolverConfig.preset("ifusion")
    steps = [annealed_timestep(config, step, 1000) for step in range(config.start_steps)]
    assert steps[0] == 999 and steps[-1] == 10  # round((1 - s / 100) * 1000), clipped to [0, 999]
    assert all(a > b for a, b in zip(steps, steps[1:]))


def test_a_known_polar_angle_is_held_by_the_search():
    predictor = scene(2)
    result = estimate_poses(predictor, images(2), STARTS, known_polar=[0.3])
    assert result.rel_poses[0, 0] == torch.tensor(0.3).item()


def test_the_ifusion_preset_finds_held_out_oracle_poses():
    errors = []
    for index, spec in enumerate(oracle_objects()[:6]):
        views = random_camera_spheres(np.random.default_rng(300 + index), 2)
        with SceneRenderer(spec, image_size=64) as renderer:
            renders = np.stack([renderer.render(*view)[0] for view in views])
        images_ = torch.from_numpy(renders).permute(0, 3, 1, 2).float() / 127.5 - 1.0
        result = estimate_poses(RenderOracle(spec, views), images_, SolverConfig.preset("ifusion"))
        cameras = spherical_to_c2w(views)
        errors.extend(pair_errors(result.rel_poses, cameras[:1], cameras[1:])[0])
    assert np.mean(np.array(errors) < 15.0) >= 5 / 6, errors


def test_triangular_refinement_runs_after_the_search_when_asked():
    config = STARTS.updated(variant="tr", refine_steps_per_view=10)
    result = estimate_poses(scene(3), images(3), config)
    assert result.stage_samples["refinement"][1] == 2 * config.refine_steps_per_view


def test_refinement_stops_early_once_the_poses_settle():
    base = SolverConfig(**ORACLE_SOLVER_SETTINGS, azimuth_candidates=4, polar_candidates_deg=(0.0,), adjust_steps=2,
                        refine_steps_per_view=200, runner_up_steps=0)
    full = estimate_poses(scene(2), images(2), base.updated(refine_stop_steps=5))  # bound 0: never settled
    early = estimate_poses(scene(2), images(2), base.updated(refine_stop_deg=0.5, refine_stop_steps=5))
    assert full.stage_samples["refinement"][1] == 200
    assert 5 < early.stage_samples["refinement"][1] < 200


def test_adjust_top_sets_how_many_candidates_are_adjusted():
    config = SolverConfig(**ORACLE_SOLVER_SETTINGS, azimuth_candidates=4, polar_candidates_deg=(0.0, 60.0),
                          adjust_steps=3, adjust_top=2, refine_steps_per_view=0, runner_up_steps=0)
    result = estimate_poses(scene(2), images(2), config)
    assert result.stage_samples["exploration"][1] == 3 * 2


def test_the_runner_up_gate_skips_the_polish_when_no_far_candidate_is_close():
    config = SolverConfig(**ORACLE_SOLVER_SETTINGS, azimuth_candidates=4, polar_candidates_deg=(0.0,),
                          adjust_steps=2, refine_steps_per_view=10, runner_up_steps=10)
    always = estimate_poses(scene(2), images(2), config)
    never = estimate_poses(scene(2), images(2), config.updated(runner_up_gate=0.0))
    assert always.stage_samples["runner-up"][1] == 10
    assert never.stage_samples.get("runner-up", (0, 0))[1] == 0
    assert math.isclose(never.runner_up_scores[0], never.runner_up_scores[0])  # a far candidate's probe error
    assert set(PRESETS) == {"default", "fast", "live", "ifusion"}
