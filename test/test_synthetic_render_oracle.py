"""RenderOracle (test fixture): protocol, schedule, differentiable grid interpolation, true-pose minimum.

Reduced: a 10 deg render grid (the default is 5 deg) at 16 px latents, to keep each test under seconds.
"""
import math

import cv2
import numpy as np
import pytest
import torch

from idpose_core.noise_predictor import NoisePredictor
from idpose_core.spherical import relative
from idpose_core.synthetic.render_oracle import RenderOracle, scaled_linear_alphas_cumprod
from idpose_core.synthetic.scenes import CAMERA_RADIUS, SceneRenderer, oracle_objects

STEP, LATENT, RENDER = 10.0, 16, 32


@pytest.fixture(scope="module")
def scene():
    spec = oracle_objects()[0]
    views = np.radians([[60.0, 20.0, 0.0], [100.0, 130.0, 0.0]])
    views[:, 2] = CAMERA_RADIUS
    oracle = RenderOracle(spec, views, step_deg=STEP, latent_size=LATENT, render_size=RENDER)
    return oracle, oracle.encode(torch.zeros(2, 3, 64, 64)), views


def errors(oracle, encoded, poses, t=200):
    count = len(poses)
    return oracle.noise_error(encoded, torch.zeros(count, dtype=torch.long), torch.ones(count, dtype=torch.long),
                              poses, torch.full((count,), t), torch.randn(count, 3, LATENT, LATENT))


def test_it_is_a_noise_predictor():
    oracle = RenderOracle(oracle_objects()[0], np.zeros((2, 3)) + 1.0, step_deg=STEP, latent_size=LATENT,
                          render_size=RENDER)
    assert isinstance(oracle, NoisePredictor)
    assert oracle.num_train_timesteps == 1000


def test_schedule_is_zero123_scaled_linear():
    betas = np.linspace(math.sqrt(0.00085), math.sqrt(0.012), 1000) ** 2
    expected = np.cumprod(1.0 - betas)
    assert np.allclose(scaled_linear_alphas_cumprod().numpy(), expected, rtol=1e-5)


def test_grid_nodes_are_the_renders():
    spec = oracle_objects()[1]
    oracle = RenderOracle(spec, np.zeros((2, 3)), step_deg=STEP, latent_size=LATENT, render_size=RENDER)
    with SceneRenderer(spec, image_size=RENDER) as renderer:
        rgb, _ = renderer.render(math.radians(70.0), math.radians(250.0), CAMERA_RADIUS)
    expected = cv2.resize(rgb, (LATENT, LATENT), interpolation=cv2.INTER_AREA).astype(np.float32) / 127.5 - 1.0
    image = oracle.images(torch.tensor([[math.radians(70.0), math.radians(250.0), 0.0]]))[0]
    assert np.allclose(image.permute(1, 2, 0).numpy(), expected, atol=1e-5)


def test_azimuth_wraps_and_polar_reflects_over_the_pole(scene):
    oracle, _, _ = scene
    eps = 1e-4
    near_zero = oracle.images(torch.tensor([[1.0, eps, 0.0], [1.0, 2 * math.pi - eps, 0.0]]))
    assert (near_zero[0] - near_zero[1]).abs().max() < 1e-2
    reflected = oracle.images(torch.tensor([[-0.4, 1.0, 0.0], [0.4, 1.0 + math.pi, 0.0]]))
    assert torch.allclose(reflected[0], reflected[1], atol=1e-5)


def test_true_relative_pose_is_the_global_minimum(scene):
    oracle, encoded, views = scene
    true = torch.tensor(relative(views[0], views[1]), dtype=torch.float32)
    assert errors(oracle, encoded, true[None]).item() < 1e-8
    sweep = true.repeat(72, 1)
    sweep[:, 1] = torch.arange(72) * (2 * math.pi / 72)
    sweep_errors = errors(oracle, encoded, sweep)
    best = float(sweep[int(torch.argmin(sweep_errors)), 1])
    gap = abs((best - float(true[1]) + math.pi) % (2 * math.pi) - math.pi)
    assert gap <= math.radians(5.0 + 1e-3), "the sweep's best azimuth must be the grid point nearest the truth"
    assert sweep_errors.max() > 0.1


def test_error_is_differentiable_and_matches_finite_differences(scene):
    oracle, encoded, views = scene
    true = torch.tensor(relative(views[0], views[1]), dtype=torch.float64)
    pose = (true + torch.tensor([0.05, 0.13, 0.0], dtype=torch.float64))[None].requires_grad_(True)
    encoded64 = type(encoded)(encoded.latents.double(), {k: v.double() for k, v in encoded.conditioning.items()})
    noise = torch.randn(1, 3, LATENT, LATENT, dtype=torch.float64)

    def error(p):
        return oracle.noise_error(encoded64, torch.tensor([0]), torch.tensor([1]), p, torch.tensor([200]), noise)

    error(pose).sum().backward()
    for axis in (0, 1):
        step = torch.zeros(1, 3, dtype=torch.float64)
        step[0, axis] = 1e-6
        numeric = (error(pose.detach() + step) - error(pose.detach() - step)).item() / 2e-6
        assert math.isclose(pose.grad[0, axis].item(), numeric, rel_tol=1e-3, abs_tol=1e-6)
    assert pose.grad[0, 2] == 0.0  # fixed radius: the relative radius has no effect


def test_noise_cancels_for_the_ideal_denoiser_but_the_level_scales_the_error(scene):
    oracle, encoded, views = scene
    pose = torch.tensor(relative(views[0], views[1]), dtype=torch.float32)[None] + 0.2
    first, second = errors(oracle, encoded, pose), errors(oracle, encoded, pose)
    assert torch.allclose(first, second, rtol=1e-4)
    abar = scaled_linear_alphas_cumprod()
    ratio = (errors(oracle, encoded, pose, t=600) / errors(oracle, encoded, pose, t=200)).item()
    expected = (abar[600] / (1 - abar[600]) / (abar[200] / (1 - abar[200]))).item()
    assert math.isclose(ratio, expected, rel_tol=1e-3)


def test_encode_checks_the_view_count(scene):
    oracle, _, _ = scene
    with pytest.raises(ValueError, match="views"):
        oracle.encode(torch.zeros(3, 3, 64, 64))
    with pytest.raises(ValueError, match="step_deg"):
        RenderOracle(oracle_objects()[0], np.zeros((2, 3)), step_deg=7.0)
