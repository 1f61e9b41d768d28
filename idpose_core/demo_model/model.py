"""The small view-conditioned diffusion model: Zero-1-to-3's parts at toy size, in pixel space.

Parts (same classes as Zero-1-to-3): a diffusers ``UNet2DConditionModel`` noise predictor, a
transformers ``CLIPVisionModelWithProjection`` reference encoder, and ``cc_projection`` (Linear
embedding + 4 -> embedding) producing the single cross-attention token. Deviation: the pose's
Fourier features (optionally with the cc_projection token) also enter the timestep embedding through
the UNet's projection class embedding, and optionally scale and shift every ResNet block (FiLM);
with ``absolute_view_conditioning`` those features describe the absolute target view, the relative
pose composed onto the reference view that ``view_head`` reads from the reference embedding; with
``reference_warp`` the UNet also sees the reference warped into the target view through a sphere.
"""
from __future__ import annotations

from pathlib import Path

import torch
import torch.nn.functional as F
from diffusers import DDPMScheduler, UNet2DConditionModel
from safetensors.torch import load_file, save_file
from torch import nn
from transformers import CLIPVisionModelWithProjection

from idpose_core.demo_model.config import ZERO123_POSE_DIM, DemoModelConfig
from idpose_core.demo_model.pose_features import fourier_pose_features
from idpose_core.demo_model.reference_warp import sphere_warp
from idpose_core.spherical import compose
from idpose_core.zero123.zero123_predictor import pose_features

WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"


class DemoDiffusionModel(nn.Module):
    """Noise predictor ``f(x_t, x_ref, p, t)`` on ``config.resolution``-pixel RGB images in [-1, 1]."""

    def __init__(self, config: DemoModelConfig):
        super().__init__()
        self.config = config.validate()
        self.unet = UNet2DConditionModel(**config.unet_kwargs())
        self.image_encoder = CLIPVisionModelWithProjection(config.encoder_config())
        self.cc_projection = nn.Linear(config.embedding_dim + ZERO123_POSE_DIM, config.embedding_dim)
        self.view_head = nn.Linear(config.embedding_dim, 3) if config.absolute_view_conditioning else None
        self.scheduler = DDPMScheduler(num_train_timesteps=config.num_train_timesteps,
                                       beta_start=config.beta_start, beta_end=config.beta_end,
                                       beta_schedule=config.beta_schedule,
                                       prediction_type=config.prediction_type)

    def downsample(self, images: torch.Tensor) -> torch.Tensor:
        """Images (N, 3, H, W) in [-1, 1] -> (N, 3, r, r) at the model resolution (area-averaged: box filter)."""
        if images.ndim != 4 or images.shape[1] != 3:
            raise ValueError(f"images must be (N, 3, H, W), got {tuple(images.shape)}")
        size = self.config.resolution
        if images.shape[-2:] == (size, size):
            return images
        return F.interpolate(images, size=(size, size), mode="area")

    def embed(self, images: torch.Tensor) -> torch.Tensor:
        """Model-resolution images (N, 3, r, r) -> CLIP image embeddings (N, D)."""
        return self.image_encoder(pixel_values=images).image_embeds

    def add_noise(self, clean: torch.Tensor, noise: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """``x_t = sqrt(abar_t) x_0 + sqrt(1 - abar_t) eps`` for (B, 3, r, r) tensors and steps t (B,)."""
        return self.scheduler.add_noise(clean, noise, t)

    def predict_noise(self, noisy: torch.Tensor, reference: torch.Tensor, embedding: torch.Tensor,
                      pose: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """Predicted noise (B, 3, r, r) from noisy targets, reference images (B, 3, r, r), reference
        embeddings (B, D), relative poses (B, 3) and steps t (B,)."""
        output = self.model_output(noisy, reference, embedding, pose, t)
        if self.config.prediction_type == "epsilon":
            return output
        alpha_bar = self.scheduler.alphas_cumprod.to(noisy.device)[t].to(noisy.dtype).view(-1, 1, 1, 1)
        return (noisy - alpha_bar.sqrt() * output) / (1 - alpha_bar).sqrt()

    def model_output(self, noisy: torch.Tensor, reference: torch.Tensor, embedding: torch.Tensor,
                     pose: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """The UNet's raw output (B, 3, r, r): noise or clean target, as ``config.prediction_type`` says.

        The pose path (view head, composition, features, cc_projection) runs in float32 even under a
        reduced-precision autocast: bfloat16 there flipped answers that float32 got right.
        """
        inputs = [noisy, reference]
        with torch.autocast(noisy.device.type, enabled=False):
            embedding = embedding.float()
            token = self.cc_projection(torch.cat([embedding, pose_features(pose).to(embedding.dtype)], -1))
            if self.config.reference_warp:
                inputs.append(sphere_warp(reference.float(), pose, self.config.warp_radius).to(noisy.dtype))
            if self.view_head is not None:
                pose = compose(self.reference_view(embedding), pose)
            class_input = fourier_pose_features(pose).to(embedding.dtype)
            if self.config.token_in_timestep_embedding:
                class_input = torch.cat([class_input, token], -1)
        return self.unet(torch.cat(inputs, 1), t, encoder_hidden_states=token[:, None],
                         class_labels=class_input).sample

    def view_head_output(self, embedding: torch.Tensor) -> torch.Tensor:
        """Reference embeddings (B, D) -> (B, 3): polar - pi/2, sin azimuth, cos azimuth of the reference view."""
        if self.view_head is None:
            raise ValueError("this model has no view head (absolute_view_conditioning is off)")
        return self.view_head(embedding)

    def reference_view(self, embedding: torch.Tensor) -> torch.Tensor:
        """Reference embeddings (B, D) -> absolute reference views (B, 3): (polar, azimuth, 0) radians."""
        out = self.view_head_output(embedding)
        polar = out[:, 0] + torch.pi / 2
        azimuth = torch.atan2(out[:, 1], out[:, 2])
        return torch.stack([polar, azimuth, torch.zeros_like(polar)], -1)

    def save_pretrained(self, folder: Path) -> None:
        """Write ``config.json`` and ``model.safetensors`` into ``folder``."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        self.config.save(folder / CONFIG_FILE)
        save_file({k: v.detach().contiguous() for k, v in self.state_dict().items()}, str(folder / WEIGHTS_FILE))

    @classmethod
    def from_pretrained(cls, folder: Path) -> DemoDiffusionModel:
        """Rebuild from a folder written by ``save_pretrained`` (safetensors only)."""
        folder = Path(folder)
        for name in (CONFIG_FILE, WEIGHTS_FILE):
            if not (folder / name).is_file():
                raise FileNotFoundError(f"demo model folder {folder} has no {name}")
        model = cls(DemoModelConfig.load(folder / CONFIG_FILE))
        model.load_state_dict(load_file(str(folder / WEIGHTS_FILE)))
        return model
