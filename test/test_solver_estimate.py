"""estimate_poses mechanics on a render-oracle scene: validation, batching, counters, progress, cancel, seeds.

Reduced: 10 deg oracle grid at 16 px; 4 azimuth x 3 polar candidates, 4 adjust steps, 30 refinement
and 10 runner-up steps per view (paper: 8 x 5, 10, 600); the oracle's learning rates
(``ORACLE_SOLVER_SETTINGS``) with a probe batch of 2.
"""
import math
import threading

import numpy as np
import pytest
import torch

from idpose_core.solver import Cancelled, SolverConfig, SolverResult, estimate_poses
from idpose_core.synthetic.render_oracle import ORACLE_SOLVER_SETTINGS, RenderOracle
from idpose_core.synthetic.scenes import oracle_objects, random_camera_spheres

CONFIG = SolverConfig(**{**ORACLE_SOLVER_SETTINGS, "probe_batch": 2}, azimuth_candidates=4,
                      polar_candidates_deg=(-60.0, 0.0, 60.0), adjust_steps=4, refine_steps_per_view=30,
                      runner_up_steps=10, average_last=5, max_batch=16)


class CountingPredictor:
    """The real oracle, with a record of every call made to it (batch sizes, differentiated or not)."""

    def __init__(self, oracle: RenderOracle):
        self.oracle = oracle
        self.num_train_timesteps = oracle.num_train_timesteps
        self.solver_defaults = oracle.solver_defaults
        self.encode_calls = 0
        self.calls: list[tuple[int, bool]] = []
        self.back_propagated = 0  # differentiated calls whose errors have received their gradient
        self.pending_at_call: list[int] = []  # per differentiated call: earlier ones not yet back-propagated

    def encode(self, images):
        self.encode_calls += 1
        return self.oracle.encode(images)

    def noise_error(self, views, ref, tgt, pose, t, noise):
        self.calls.append((len(ref), pose.requires_grad))
        errors = self.oracle.noise_error(views, ref, tgt, pose, t, noise)
        if pose.requires_grad:
            earlier = sum(grad for _, grad in self.calls[:-1])
            self.pending_at_call.append(earlier - self.back_propagated)
            errors.register_hook(self._count_backward)
        return errors

    def _count_backward(self, grad):
        self.back_propagated += 1



def scene(count: int) -> CountingPredictor:
    views = random_camera_spheres(np.random.default_rng(7), count)
    return CountingPredictor(RenderOracle(oracle_objects()[2], views, step_deg=10.0, latent_size=16, render_size=32))


def images(count: int) -> torch.Tensor:
    return torch.zeros(count, 3, 32, 32)


def test_result_has_the_promised_shapes_and_counts():
    predictor = scene(3)
    result = estimate_poses(predictor, images(3), CONFIG)
    assert isinstance(result, SolverResult)
    assert result.rel_poses.shape == (2, 3) and result.runner_up_poses.shape == (2, 3)
    assert result.scores.shape == result.runner_up_scores.shape == result.ambiguous.shape == (2,)
    assert result.ambiguous.dtype == bool
    assert ((result.rel_poses[:, 1] >= 0) & (result.rel_poses[:, 1] < 2 * math.pi)).all()
    assert set(result.stage_seconds) >= {"encode", "exploration", "selection", "refinement", "scoring"}
    assert predictor.encode_calls == 1
    assert result.forward_samples == sum(size for size, _ in predictor.calls)
    assert result.backward_samples == sum(size for size, grad in predictor.calls if grad)
    refine_and_polish = (CONFIG.refine_steps_per_view + CONFIG.runner_up_steps) * 2
    adjusted = 2 * (len(CONFIG.polar_candidates_deg) * CONFIG.azimuth_candidates // 2)
    assert result.backward_samples == refine_and_polish + CONFIG.adjust_steps * adjusted
    assert result.stage_samples["exploration"][1] == CONFIG.adjust_steps * adjusted
    assert result.stage_samples["refinement"][1] == CONFIG.refine_steps_per_view * 2
    assert sum(f for f, _ in result.stage_samples.values()) == result.forward_samples
    assert sum(b for _, b in result.stage_samples.values()) == result.backward_samples


def test_probes_fill_batches_up_to_max_batch():
    predictor = scene(3)
    estimate_poses(predictor, images(3), CONFIG)
    probes = [size for size, grad in predictor.calls if not grad]
    assert max(size for size, _ in predictor.calls) <= CONFIG.max_batch
    # exploration, re-probe, selection and scoring: at most one part-filled call each
    assert sum(size < CONFIG.max_batch for size in probes) <= 4
    assert len(probes) <= math.ceil(sum(probes) / CONFIG.max_batch) + 4


def test_gradient_steps_back_propagate_chunk_by_chunk():
    predictor = scene(4)  # 3 views x 6 adjusted candidates = 18 samples per adjust step
    estimate_poses(predictor, images(4), CONFIG)
    differentiated = [size for size, grad in predictor.calls if grad]
    assert max(differentiated) == CONFIG.grad_batch < 18
    assert predictor.pending_at_call == [0] * len(differentiated), \
        "a differentiated chunk ran before the previous one was back-propagated"


def test_chunked_gradients_give_the_same_poses():
    whole = estimate_poses(scene(4), images(4), CONFIG.updated(grad_batch=64))
    chunked = estimate_poses(scene(4), images(4), CONFIG.updated(grad_batch=5))
    assert np.allclose(whole.rel_poses, chunked.rel_poses, atol=1e-5)
    assert whole.backward_samples == chunked.backward_samples


def test_progress_reports_every_stage_up_to_its_total():
    seen: dict[str, list[tuple[int, int]]] = {}
    estimate_poses(scene(3), images(3), CONFIG, progress=lambda s, d, t: seen.setdefault(s, []).append((d, t)))
    assert list(seen) == ["exploration", "selection", "refinement", "runner-up", "scoring"]
    for stage, reports in seen.items():
        done = [d for d, _ in reports]
        assert done == sorted(done), f"{stage} progress went backwards"
        assert reports[-1][0] == reports[-1][1], f"{stage} ended at {reports[-1]}"


def test_cancel_stops_within_one_step():
    predictor, cancel = scene(2), threading.Event()
    calls_at_cancel = []

    def progress(stage, done, total):
        if stage == "refinement" and done == 5 and not cancel.is_set():
            cancel.set()
            calls_at_cancel.append(len(predictor.calls))

    with pytest.raises(Cancelled):
        estimate_poses(predictor, images(2), CONFIG, progress=progress, cancel=cancel)
    assert len(predictor.calls) == calls_at_cancel[0], "no predictor call may follow the cancel"


def test_a_preset_cancel_stops_before_any_sample():
    predictor, cancel = scene(2), threading.Event()
    cancel.set()
    with pytest.raises(Cancelled):
        estimate_poses(predictor, images(2), CONFIG, cancel=cancel)
    assert predictor.calls == []


def test_a_seeded_run_repeats_exactly():
    first = estimate_poses(scene(3), images(3), CONFIG)
    second = estimate_poses(scene(3), images(3), CONFIG)
    for name in ("rel_poses", "scores", "runner_up_poses", "runner_up_scores", "ambiguous"):
        assert np.array_equal(getattr(first, name), getattr(second, name), equal_nan=True), name


@pytest.mark.parametrize(
    "bad_images, message",
    [
        (torch.zeros(1, 3, 32, 32), "at least 2 views"),
        ([torch.zeros(3, 32, 32), torch.zeros(3, 24, 24)], "same size"),
        (torch.zeros(2, 1, 32, 32), r"\(N, 3, H, W\)"),
        (torch.zeros(2, 3, 32, 32).index_fill_(0, torch.tensor([1]), math.nan), r"views \[1\].*NaN"),
        (torch.full((2, 3, 32, 32), 3.0), r"\[-1, 1\]"),
    ],
)
def test_bad_images_raise_before_any_model_call(bad_images, message):
    predictor = scene(2)
    with pytest.raises(ValueError, match=message):
        estimate_poses(predictor, bad_images, CONFIG)
    assert predictor.encode_calls == 0 and predictor.calls == []


def test_bad_config_raises_before_any_model_call():
    predictor = scene(2)
    with pytest.raises(ValueError, match="refine_lr"):
        estimate_poses(predictor, images(2), SolverConfig(refine_lr=-1.0))
    assert predictor.encode_calls == 0 and predictor.calls == []


def test_a_list_of_views_is_accepted():
    result = estimate_poses(scene(2), [torch.zeros(3, 32, 32)] * 2, CONFIG)
    assert result.rel_poses.shape == (1, 3)


def relative_polar(predictor: CountingPredictor) -> list[float]:
    """The relative polar angles of views 1.. from the anchor, as gravity would give them."""
    views = predictor.oracle.views_sph.numpy()
    return list(views[1:, 0] - views[0, 0])


def test_live_without_gravity_runs_fast_and_says_so():
    rates = {name: ORACLE_SOLVER_SETTINGS[name] for name in ("adjust_lr", "refine_lr")}
    live, fast = SolverConfig.preset("live", **rates), SolverConfig.preset("fast", **rates)
    fell_back, ran_fast = estimate_poses(scene(2), images(2), live), estimate_poses(scene(2), images(2), fast)
    assert "'fast' schedule" in fell_back.note and "no view's elevation is known" in fell_back.note
    assert ran_fast.note == ""
    np.testing.assert_array_equal(fell_back.rel_poses, ran_fast.rel_poses)
    assert fell_back.stage_samples == ran_fast.stage_samples


def test_live_with_gravity_probes_the_azimuth_coarse_to_fine_without_adjust_steps():
    predictor = scene(2)
    live = SolverConfig.preset("live", refine_lr=ORACLE_SOLVER_SETTINGS["refine_lr"])
    result = estimate_poses(predictor, images(2), live, known_polar=relative_polar(predictor))
    probe = 2 * live.probe_batch
    grid, narrowed = live.azimuth_candidates, 2 * live.keep_top * live.azimuth_refinements
    forward, differentiated = result.stage_samples["exploration"]
    assert differentiated == 0 and result.note == ""
    assert grid * probe < forward <= (grid + narrowed) * probe
    assert result.stage_samples["refinement"][1] <= live.refine_steps_per_view


def test_narrowing_finds_an_azimuth_between_grid_points():
    """With the polar angle known and no refinement, the answer can only be a probed azimuth: 4 grid azimuths
    (90 deg apart) narrowed 3 times (by 45, 22.5, 11.25 deg) come within one last step of the truth."""
    predictor = scene(2)
    views = predictor.oracle.views_sph.numpy()
    truth = float(np.degrees((views[1, 1] - views[0, 1]) % (2 * math.pi)))
    coarse = SolverConfig(**{**ORACLE_SOLVER_SETTINGS, "probe_batch": 2}, azimuth_candidates=4, adjust_steps=0,
                          refine_steps_per_view=0, runner_up_steps=0, keep_top=1)
    fine = coarse.updated(azimuth_refinements=3)
    errors = []
    for config in (coarse, fine):
        found = np.degrees(estimate_poses(predictor, images(2), config, known_polar=relative_polar(predictor))
                           .rel_poses[0, 1])
        errors.append(abs((found - truth + 180.0) % 360.0 - 180.0))
    assert errors[1] <= 90.0 / 8 < errors[0]
