"""Zero-1-to-3 architecture configurations: the released full size and a tiny one for tests.

A ``Zero123Config`` holds the constructor arguments of each diffusers / transformers part, so the
same code builds a random model (tests, benchmarks) or the skeleton that released weights load into.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any

# OpenAI CLIP pixel statistics, as CLIPImageProcessor and the original FrozenCLIPImageEmbedder use.
CLIP_MEAN = (0.48145466, 0.4578275, 0.40821073)
CLIP_STD = (0.26862954, 0.26130258, 0.27577711)

# The relative pose enters as [d_polar, sin d_az, cos d_az, d_radius], appended to the CLIP embedding.
POSE_FEATURES = 4

# Zero-1-to-3's training schedule (LDM config: linear_start 0.00085, linear_end 0.012, 1000 steps)
# in the form its diffusers conversions store in scheduler/scheduler_config.json.
SCHEDULER = MappingProxyType(
    {
        "num_train_timesteps": 1000,
        "beta_start": 0.00085,
        "beta_end": 0.012,
        "beta_schedule": "scaled_linear",
        "clip_sample": False,
        "set_alpha_to_one": False,
        "steps_offset": 1,
        "prediction_type": "epsilon",
    }
)


def _frozen(mapping: Mapping[str, Any]) -> Mapping[str, Any]:
    return MappingProxyType(dict(mapping))


@dataclass(frozen=True)
class Zero123Config:
    """Constructor kwargs of every part: ``UNet2DConditionModel``, ``AutoencoderKL``, ``CLIPVisionConfig``.

    The cc_projection is implied: ``image_encoder.projection_dim + 4 -> unet.cross_attention_dim``
    (772 -> 768 at full size). The UNet sees the noisy target latent and the reference latent
    stacked, so ``unet.in_channels == 2 * vae.latent_channels``.
    """

    unet: Mapping[str, Any]
    vae: Mapping[str, Any]
    image_encoder: Mapping[str, Any]
    scheduler: Mapping[str, Any] = field(default_factory=lambda: SCHEDULER)

    @property
    def projection_in(self) -> int:
        return int(self.image_encoder["projection_dim"]) + POSE_FEATURES

    @property
    def projection_out(self) -> int:
        return int(self.unet["cross_attention_dim"])

    def updated(self, **parts: Mapping[str, Any]) -> Zero123Config:
        """A copy with some kwargs of some parts changed, e.g. ``updated(unet={"layers_per_block": 1})``."""
        return replace(self, **{name: _frozen({**getattr(self, name), **values}) for name, values in parts.items()})

    @classmethod
    def full(cls) -> Zero123Config:
        """The released Zero-1-to-3 (105000 / 165000 / XL): SD-1 UNet with 8 input channels, SD VAE, ViT-L/14."""
        return cls(
            unet=_frozen(
                dict(
                    sample_size=32,
                    in_channels=8,
                    out_channels=4,
                    down_block_types=("CrossAttnDownBlock2D",) * 3 + ("DownBlock2D",),
                    up_block_types=("UpBlock2D",) + ("CrossAttnUpBlock2D",) * 3,
                    block_out_channels=(320, 640, 1280, 1280),
                    layers_per_block=2,
                    cross_attention_dim=768,
                    attention_head_dim=8,
                )
            ),
            vae=_frozen(
                dict(
                    in_channels=3,
                    out_channels=3,
                    down_block_types=("DownEncoderBlock2D",) * 4,
                    up_block_types=("UpDecoderBlock2D",) * 4,
                    block_out_channels=(128, 256, 512, 512),
                    layers_per_block=2,
                    latent_channels=4,
                    sample_size=256,
                    scaling_factor=0.18215,
                )
            ),
            image_encoder=_frozen(
                dict(
                    hidden_size=1024,
                    intermediate_size=4096,
                    projection_dim=768,
                    num_hidden_layers=24,
                    num_attention_heads=16,
                    image_size=224,
                    patch_size=14,
                    hidden_act="quick_gelu",
                )
            ),
        )

    @classmethod
    def tiny(cls) -> Zero123Config:
        """Same family at toy widths (UNet 32/64, VAE 32/64 = 2x downsampling, CLIP 32 px, 32-d tokens)."""
        return cls(
            unet=_frozen(
                dict(
                    sample_size=16,
                    in_channels=8,
                    out_channels=4,
                    down_block_types=("CrossAttnDownBlock2D", "DownBlock2D"),
                    up_block_types=("UpBlock2D", "CrossAttnUpBlock2D"),
                    block_out_channels=(32, 64),
                    layers_per_block=2,
                    cross_attention_dim=32,
                    attention_head_dim=8,
                )
            ),
            vae=_frozen(
                dict(
                    in_channels=3,
                    out_channels=3,
                    down_block_types=("DownEncoderBlock2D",) * 2,
                    up_block_types=("UpDecoderBlock2D",) * 2,
                    block_out_channels=(32, 64),
                    layers_per_block=1,
                    latent_channels=4,
                    sample_size=32,
                    scaling_factor=0.18215,
                )
            ),
            image_encoder=_frozen(
                dict(
                    hidden_size=32,
                    intermediate_size=64,
                    projection_dim=32,
                    num_hidden_layers=2,
                    num_attention_heads=4,
                    image_size=32,
                    patch_size=8,
                    hidden_act="quick_gelu",
                )
            ),
        )
