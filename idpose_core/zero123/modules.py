"""The five parts of Zero-1-to-3, built from diffusers / transformers classes, and their consistency rules."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch
from diffusers import AutoencoderKL, DDIMScheduler, UNet2DConditionModel
from transformers import CLIPVisionConfig, CLIPVisionModelWithProjection

from idpose_core.zero123.config import CLIP_MEAN, CLIP_STD, POSE_FEATURES, Zero123Config
from idpose_core.zero123.errors import ModelLoadError


@dataclass
class Zero123Modules:
    """UNet, VAE, CLIP image encoder, the (embedding + pose) -> token projection and the schedule.

    ``clip_size``, ``clip_mean`` and ``clip_std`` are the CLIP input resolution and pixel statistics
    (the folder's ``feature_extractor`` when present).
    """

    unet: UNet2DConditionModel
    vae: AutoencoderKL
    image_encoder: CLIPVisionModelWithProjection
    cc_projection: torch.nn.Linear
    scheduler: DDIMScheduler
    clip_size: int
    clip_mean: tuple[float, ...] = CLIP_MEAN
    clip_std: tuple[float, ...] = CLIP_STD

    def parameter_modules(self) -> tuple[torch.nn.Module, ...]:
        """The four parts that hold weights."""
        return (self.unet, self.vae, self.image_encoder, self.cc_projection)

    def freeze(self) -> None:
        """Inference only: eval mode and no weight gradients, so backward reaches the pose alone."""
        for module in self.parameter_modules():
            module.eval()
            module.requires_grad_(False)


def build_modules(config: Zero123Config, seed: int | None = 0) -> Zero123Modules:
    """Construct every part from ``config`` with the libraries' random initialisation (seeded)."""
    with torch.random.fork_rng(devices=[]):
        if seed is not None:
            torch.manual_seed(seed)
        image_encoder = CLIPVisionModelWithProjection(CLIPVisionConfig(**config.image_encoder))
        return Zero123Modules(
            unet=UNet2DConditionModel(**config.unet),
            vae=AutoencoderKL(**config.vae),
            image_encoder=image_encoder,
            cc_projection=torch.nn.Linear(config.projection_in, config.projection_out),
            scheduler=DDIMScheduler(**config.scheduler),
            clip_size=int(config.image_encoder["image_size"]),
        )


def inconsistencies(modules: Zero123Modules) -> list[str]:
    """Shape rules that tie the parts together; an empty list means the parts fit."""
    unet, vae = modules.unet.config, modules.vae.config
    projection_dim = modules.image_encoder.config.projection_dim
    linear = modules.cc_projection
    problems = []
    if unet.in_channels != 2 * vae.latent_channels:
        problems.append(
            f"unet in_channels {unet.in_channels} != 2 x vae latent_channels {vae.latent_channels} "
            "(noisy target latent + reference latent)"
        )
    if unet.out_channels != vae.latent_channels:
        problems.append(f"unet out_channels {unet.out_channels} != vae latent_channels {vae.latent_channels}")
    if linear.in_features != projection_dim + POSE_FEATURES:
        problems.append(
            f"cc_projection takes {linear.in_features} features, expected CLIP projection_dim "
            f"{projection_dim} + {POSE_FEATURES} pose features"
        )
    if linear.out_features != unet.cross_attention_dim:
        problems.append(
            f"cc_projection gives {linear.out_features} features, unet cross_attention_dim is "
            f"{unet.cross_attention_dim}"
        )
    return problems


def require_fit(modules: Zero123Modules, path: str | Path) -> Zero123Modules:
    """``modules`` when they fit together, else the ``ModelLoadError`` of the file or folder ``path``."""
    problems = inconsistencies(modules)
    if problems:
        raise ModelLoadError(path, "parts do not fit together: " + "; ".join(problems))
    return modules
