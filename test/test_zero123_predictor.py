"""Zero123Predictor on the tiny random model (Zero123Config.tiny: same architecture family, toy widths).

Reduced: 32 px images, a 2-level UNet (32/64 channels), a 2-layer 32-d CLIP; 3 views, batches of 4.
"""
import numpy as np
import pytest
import torch
from diffusers import DDPMScheduler
from transformers import CLIPImageProcessor

from idpose_core.noise_predictor import NoisePredictor
from idpose_core.zero123 import Zero123Predictor

SIZE = 32




@pytest.fixture(scope="module")
def predictor():
    return Zero123Predictor.tiny(seed=0)


@pytest.fixture(scope="module")
def images():
    generator = torch.Generator().manual_seed(1)
    return torch.rand(3, 3, SIZE, SIZE, generator=generator) * 2 - 1


@pytest.fixture(scope="module")
def views(predictor, images):
    return predictor.encode(images)


def batch(views, size=4, seed=2):
    """A reproducible noise_error batch: pairs, poses, steps near t = 200, noise."""
    generator = torch.Generator().manual_seed(seed)
    ref = torch.tensor([0, 1, 2, 0])[:size]
    tgt = torch.tensor([1, 2, 0, 2])[:size]
    pose = torch.rand(size, 3, generator=generator) * torch.tensor([1.0, 6.28, 0.5]) - torch.tensor([0.5, 0, 0.25])
    t = torch.randint(200, 210, (size,), generator=generator)
    noise = torch.randn(size, *views.noise_shape, generator=generator)
    return ref, tgt, pose, t, noise


def test_is_a_noise_predictor(predictor):
    assert isinstance(predictor, NoisePredictor)
    assert predictor.num_train_timesteps == 1000


def test_encode_shapes(views):
    assert views.latents.shape == (3, 4, SIZE // 2, SIZE // 2)
    assert views.conditioning["ref_latents"].shape == views.latents.shape
    assert views.conditioning["image_embeds"].shape == (3, 32)


def test_noise_error_matches_the_zero123_conditioning_written_out(predictor, images, views):
    """Rebuild one error from the paper's recipe with the raw parts and diffusers' DDPM maths."""
    modules = predictor.modules
    ref, tgt, pose, t, noise = batch(views)
    scheduler = DDPMScheduler(num_train_timesteps=1000, beta_start=0.00085, beta_end=0.012,
                              beta_schedule="scaled_linear")
    with torch.no_grad():
        mode = modules.vae.encode(images).latent_dist.mode()
        noisy = scheduler.add_noise(0.18215 * mode[tgt], noise, t)
        embeds = modules.image_encoder(pixel_values=predictor.clip_pixels(images)).image_embeds
        pose_vector = torch.stack([pose[:, 0], pose[:, 1].sin(), pose[:, 1].cos(), pose[:, 2]], dim=1)
        token = modules.cc_projection(torch.cat([embeds[ref], pose_vector], dim=1))[:, None]
        eps = modules.unet(torch.cat([noisy, mode[ref]], dim=1), t, encoder_hidden_states=token).sample
        expected = ((eps - noise) ** 2).mean(dim=(1, 2, 3))
        got = predictor.noise_error(views, ref, tgt, pose, t, noise)
    torch.testing.assert_close(got, expected, rtol=1e-5, atol=1e-6)


def test_clip_pixels_match_clip_image_processor(predictor, tmp_path):
    """At the CLIP input size the torch preprocessing equals CLIPImageProcessor on the saved config."""
    predictor.save_pretrained(tmp_path)
    processor = CLIPImageProcessor.from_pretrained(tmp_path / "feature_extractor")
    rgb = np.random.default_rng(0).integers(0, 256, (SIZE, SIZE, 3), dtype=np.uint8)
    expected = torch.as_tensor(np.asarray(processor(images=rgb, return_tensors="np")["pixel_values"]))
    images = torch.as_tensor(rgb).permute(2, 0, 1)[None].float() / 127.5 - 1
    torch.testing.assert_close(predictor.clip_pixels(images), expected, rtol=1e-4, atol=1e-4)


def test_noise_error_shape_and_determinism(predictor, views):
    args = batch(views)
    first = predictor.noise_error(views, *args)
    second = predictor.noise_error(views, *args)
    assert first.shape == (4,)
    assert torch.isfinite(first).all() and (first > 0).all()
    torch.testing.assert_close(first, second, rtol=0, atol=0)


def test_gradient_reaches_the_pose_and_nothing_else(predictor, views):
    ref, tgt, pose, t, noise = batch(views)
    pose = pose.clone().requires_grad_(True)
    predictor.noise_error(views, ref, tgt, pose, t, noise).sum().backward()
    assert torch.isfinite(pose.grad).all()
    assert pose.grad[:, :2].abs().sum() > 0
    assert all(p.grad is None and not p.requires_grad
               for module in predictor.modules.parameter_modules() for p in module.parameters())


def test_batch_equals_singles_and_chunking(views):
    """One batched UNet call, chunks of 3, and one-by-one calls agree."""
    chunked = Zero123Predictor.tiny(seed=0, max_batch=3)
    single = Zero123Predictor.tiny(seed=0, max_batch=1)
    whole = Zero123Predictor.tiny(seed=0, max_batch=64)
    args = batch(views)
    expected = whole.noise_error(views, *args)
    torch.testing.assert_close(chunked.noise_error(views, *args), expected, rtol=1e-5, atol=1e-7)
    singles = torch.cat([single.noise_error(views, *(a[i : i + 1] for a in args)) for i in range(4)])
    torch.testing.assert_close(singles, expected, rtol=1e-5, atol=1e-7)


def test_cached_encode_equals_recomputation(predictor, images, views):
    again = predictor.encode(images)
    torch.testing.assert_close(again.latents, views.latents, rtol=0, atol=0)
    for key, value in views.conditioning.items():
        torch.testing.assert_close(again.conditioning[key], value, rtol=0, atol=0)
    singles = [predictor.encode(images[i : i + 1]) for i in range(3)]
    torch.testing.assert_close(torch.cat([s.latents for s in singles]), views.latents, rtol=1e-5, atol=1e-6)


def test_pose_changes_the_error(predictor, views):
    ref, tgt, pose, t, noise = batch(views)
    shifted = pose + torch.tensor([0.3, 1.0, 0.1])
    assert not torch.allclose(predictor.noise_error(views, ref, tgt, pose, t, noise),
                              predictor.noise_error(views, ref, tgt, shifted, t, noise))


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda a: (a[0], a[1], a[2][:, :2], a[3], a[4]), "pose must have shape"),
        (lambda a: (a[0] + 5, a[1], a[2], a[3], a[4]), "ref indices"),
        (lambda a: (a[0], a[1], a[2], a[3] + 1000, a[4]), "t must lie"),
        (lambda a: (a[0], a[1], a[2], a[3], a[4][:, :2]), "noise must have shape"),
    ],
)
def test_bad_noise_error_input_is_named(predictor, views, change, message):
    with pytest.raises(ValueError, match=message):
        predictor.noise_error(views, *change(batch(views)))


def test_bad_images_are_named(predictor):
    with pytest.raises(ValueError, match="multiples of 2"):
        predictor.encode(torch.zeros(1, 3, 31, 32))
    with pytest.raises(ValueError, match=r"\(N, 3, H, W\)"):
        predictor.encode(torch.zeros(3, 32, 32))
    with pytest.raises(ValueError, match=r"\[-1, 1\]"):
        predictor.encode(torch.full((1, 3, 32, 32), 255.0))


def test_sample_view_is_an_image_and_reproducible(predictor, views):
    """Reduced: 3 DDIM steps."""
    first = predictor.sample_view(views, 0, [0.2, 0.8, 0.0], steps=3)
    second = predictor.sample_view(views, 0, [0.2, 0.8, 0.0], steps=3)
    other_pose = predictor.sample_view(views, 0, [-0.4, 3.0, 0.2], steps=3)
    assert first.shape == (3, SIZE, SIZE) and first.dtype == torch.float32
    assert first.min() >= -1 and first.max() <= 1
    torch.testing.assert_close(first, second, rtol=0, atol=0)
    assert not torch.equal(first, other_pose)
    with pytest.raises(ValueError, match="ref must index"):
        predictor.sample_view(views, 3, [0.0, 0.0, 0.0], steps=1)
