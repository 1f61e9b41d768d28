"""The demo model behind the NoisePredictor protocol (a tiny random instance), save/load, config checks."""
from __future__ import annotations

import json
import math
from dataclasses import replace

import pytest
import torch

from idpose_core.demo_model import DemoDiffusionModel, DemoModelConfig, DemoPredictor
from idpose_core.demo_model.model import CONFIG_FILE, WEIGHTS_FILE
from idpose_core.noise_predictor import NoisePredictor

TINY = DemoModelConfig(resolution=16, block_out_channels=(8, 16), norm_num_groups=4, embedding_dim=16,
                       encoder_layers=1, encoder_heads=2, resnet_time_scale_shift="scale_shift",
                       token_in_timestep_embedding=True)


@pytest.fixture(scope="module")
def tiny() -> DemoPredictor:
    """A tiny random demo model with every pose path on (the architecture family, not the weights)."""
    torch.manual_seed(0)
    return DemoPredictor(DemoDiffusionModel(TINY))


def images(count: int, size: int = 64, seed: int = 0) -> torch.Tensor:
    return torch.rand((count, 3, size, size), generator=torch.Generator().manual_seed(seed)) * 2 - 1


def test_demo_model_implements_the_protocol(tiny):
    assert isinstance(tiny, NoisePredictor)
    views = tiny.encode(images(3))
    size = tiny.model.config.resolution
    assert views.latents.shape == (3, 3, size, size)
    assert views.conditioning["embedding"].shape == (3, tiny.model.config.embedding_dim)
    noise = torch.randn((4, *views.noise_shape))
    pose = torch.tensor([[0.1, 1.0, 0.0], [0.0, 2.0, 0.0], [-0.3, 4.0, 0.0], [0.2, 0.5, 0.0]], requires_grad=True)
    errors = tiny.noise_error(views, torch.tensor([0, 1, 2, 0]), torch.tensor([1, 2, 0, 2]), pose,
                                 torch.tensor([200, 300, 400, 500]), noise)
    assert errors.shape == (4,) and torch.isfinite(errors).all()
    errors.sum().backward()
    assert pose.grad is not None and pose.grad[:, :2].abs().sum() > 0
    assert all(p.grad is None and not p.requires_grad for p in tiny.model.parameters())


def test_noise_error_is_deterministic_and_depends_on_pose(tiny):
    views = tiny.encode(images(2, seed=1))
    noise = torch.randn((2, *views.noise_shape), generator=torch.Generator().manual_seed(2))
    ref, tgt, t = torch.tensor([0, 0]), torch.tensor([1, 1]), torch.tensor([300, 300])
    first = tiny.noise_error(views, ref, tgt, torch.tensor([[0.0, 0.5, 0.0], [0.0, 3.5, 0.0]]), t, noise)
    second = tiny.noise_error(views, ref, tgt, torch.tensor([[0.0, 0.5, 0.0], [0.0, 3.5, 0.0]]), t, noise)
    torch.testing.assert_close(first, second, rtol=0, atol=0)
    assert first[0] != first[1]


def test_encode_rejects_a_wrong_shape(tiny):
    with pytest.raises(ValueError, match=r"\(N, 3, H, W\)"):
        tiny.encode(torch.zeros(3, 32, 32))


def test_save_and_load_round_trip(tmp_path):
    torch.manual_seed(0)
    model = DemoDiffusionModel(TINY)
    model.save_pretrained(tmp_path)
    loaded = DemoPredictor.from_pretrained(tmp_path)
    original = DemoPredictor(model)
    pictures = images(2, size=32)
    views_a, views_b = original.encode(pictures), loaded.encode(pictures)
    noise = torch.randn((2, *views_a.noise_shape))
    args = (torch.tensor([0, 1]), torch.tensor([1, 0]), torch.tensor([[0.2, 1.0, 0.0], [0.0, 5.0, 0.0]]),
            torch.tensor([100, 600]))
    torch.testing.assert_close(original.noise_error(views_a, *args, noise), loaded.noise_error(views_b, *args, noise))
    assert loaded.solver_defaults == {}


def test_loading_names_the_missing_file(tmp_path):
    DemoDiffusionModel(TINY).save_pretrained(tmp_path)
    (tmp_path / WEIGHTS_FILE).unlink()
    with pytest.raises(FileNotFoundError, match=WEIGHTS_FILE):
        DemoPredictor.from_pretrained(tmp_path)


def test_config_rejects_unknown_keys_and_bad_sizes(tmp_path):
    (tmp_path / CONFIG_FILE).write_text(json.dumps({"resolution": 32, "colour": "red"}))
    with pytest.raises(ValueError, match="colour"):
        DemoModelConfig.load(tmp_path / CONFIG_FILE)
    with pytest.raises(ValueError, match="resolution"):
        DemoModelConfig(resolution=30).validate()
    with pytest.raises(ValueError, match="prediction_type must be 'epsilon' or 'sample', got 'v_prediction'"):
        DemoModelConfig(prediction_type="v_prediction").validate()


def test_a_clean_target_prediction_becomes_the_exact_noise(monkeypatch):
    """prediction_type "sample": predict_noise turns the UNet's clean-target output into noise, so a
    perfect view synthesis has zero noise error at every step."""
    model = DemoDiffusionModel(TINY)
    assert model.config.prediction_type == "sample"
    clean, noise = images(3, size=16, seed=3), torch.randn(3, 3, 16, 16)
    t = torch.tensor([100, 500, 950])
    noisy = model.add_noise(clean, noise, t)
    monkeypatch.setattr(model, "model_output", lambda *args: clean)
    predicted = model.predict_noise(noisy, clean, torch.zeros(3, 16), torch.zeros(3, 3), t)
    torch.testing.assert_close(predicted, noise, rtol=1e-4, atol=1e-4)


def test_view_head_reads_the_absolute_reference_view():
    """The head's (polar - pi/2, sin az, cos az) becomes (polar, azimuth, 0); composing a relative pose onto it
    is what the UNet's pose features describe."""
    model = DemoDiffusionModel(TINY)
    polar, azimuth = 1.2, 2.5
    with torch.no_grad():
        model.view_head.weight.zero_()
        model.view_head.bias.copy_(torch.tensor([polar - torch.pi / 2, math.sin(azimuth), math.cos(azimuth)]))
    view = model.reference_view(torch.randn(2, TINY.embedding_dim))
    torch.testing.assert_close(view, torch.tensor([[polar, azimuth, 0.0]] * 2))
    without = DemoDiffusionModel(replace(TINY, absolute_view_conditioning=False))
    assert without.view_head is None
    with pytest.raises(ValueError, match="no view head"):
        without.reference_view(torch.randn(1, TINY.embedding_dim))


def test_the_reference_warp_enters_the_unet_and_carries_the_pose_gradient(monkeypatch):
    """With ``reference_warp`` the UNet takes 10 channels: the noisy target, the reference, and the reference warped
    by the pose with its visibility; a pose change then reaches the UNet's input itself."""
    config = replace(TINY, reference_warp=True, absolute_view_conditioning=False)
    model = DemoDiffusionModel(config)
    assert model.unet.config.in_channels == 10
    seen = []
    forward = model.unet.forward
    monkeypatch.setattr(model.unet, "forward", lambda sample, *args, **kwargs: seen.append(sample) or
                        forward(sample, *args, **kwargs))
    reference, noisy = images(1, size=16, seed=1), images(1, size=16, seed=2)
    for azimuth in (0.0, 1.0):
        model.model_output(noisy, reference, torch.zeros(1, 16), torch.tensor([[0.0, azimuth, 0.0]]),
                           torch.tensor([500]))
    assert torch.equal(seen[0][:, :6], seen[1][:, :6]) and not torch.equal(seen[0][:, 6:], seen[1][:, 6:])
    with pytest.raises(ValueError, match="warp_radius"):
        replace(config, warp_radius=1.5).validate()
