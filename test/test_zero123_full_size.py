"""The full-size Zero-1-to-3 architecture, built on the meta device (shapes only, no weights, no memory)."""
import pytest
import torch
from diffusers import AutoencoderKL, UNet2DConditionModel
from transformers import CLIPVisionConfig, CLIPVisionModelWithProjection

from idpose_core.zero123 import Zero123Config


@pytest.fixture(scope="module")
def parts():
    config = Zero123Config.full()
    with torch.device("meta"):
        return {
            "unet": UNet2DConditionModel(**config.unet),
            "vae": AutoencoderKL(**config.vae),
            "image_encoder": CLIPVisionModelWithProjection(CLIPVisionConfig(**config.image_encoder)),
            "cc_projection": torch.nn.Linear(config.projection_in, config.projection_out),
        }


def millions(module):
    return sum(p.numel() for p in module.parameters()) / 1e6


def test_unet_has_the_zero123_shapes(parts):
    """SD-1 UNet (859.5 M) with 8 input channels: noisy target latent + reference latent."""
    unet = parts["unet"]
    assert millions(unet) == pytest.approx(859.5, abs=0.1)
    assert unet.conv_in.weight.shape == (320, 8, 3, 3)
    assert unet.conv_out.weight.shape == (4, 320, 3, 3)
    assert unet.config.block_out_channels == (320, 640, 1280, 1280)
    assert unet.config.cross_attention_dim == 768


def test_conditioning_parts_have_the_released_shapes(parts):
    """SD VAE (83.7 M, 8x downsampling, 4 latent channels), CLIP ViT-L/14 with 768-d projection, 772 -> 768."""
    assert millions(parts["vae"]) == pytest.approx(83.65, abs=0.01)
    assert parts["vae"].config.scaling_factor == 0.18215
    clip = parts["image_encoder"]
    assert millions(clip) == pytest.approx(303.97, abs=0.01)
    assert clip.visual_projection.weight.shape == (768, 1024)
    assert parts["cc_projection"].weight.shape == (768, 772)
    assert Zero123Config.full().scheduler["beta_schedule"] == "scaled_linear"
