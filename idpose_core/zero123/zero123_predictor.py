"""Zero-1-to-3 as a ``NoisePredictor``: encode each view once, then only the UNet runs per step."""
from __future__ import annotations

from pathlib import Path

import torch
import torch.nn.functional as F

from idpose_core.devices import resolve_device
from idpose_core.noise_predictor import Views
from idpose_core.zero123.config import Zero123Config
from idpose_core.zero123.ldm_checkpoint import load_ldm_checkpoint
from idpose_core.zero123.loading import load_diffusers_folder, save_diffusers_folder
from idpose_core.zero123.modules import Zero123Modules, build_modules
from idpose_core.zero123.sampling import sample_view as ddim_sample_view


def resolve_dtype(dtype: torch.dtype | None, device: torch.device) -> torch.dtype:
    """``None`` -> float32 on CPU; bfloat16 (else float16) autocast on CUDA."""
    if dtype is not None:
        return dtype
    if device.type == "cuda":
        return torch.bfloat16 if torch.cuda.is_bf16_supported() else torch.float16
    return torch.float32


def reduced_precision(device: torch.device, dtype: torch.dtype):
    """Autocast to ``dtype`` on ``device``; a no-op for float32 (what the predictors wrap their UNet calls in)."""
    return torch.autocast(device.type, dtype=dtype, enabled=dtype != torch.float32)


def pose_features(pose: torch.Tensor) -> torch.Tensor:
    """Relative poses (B, 3) = (d_polar, d_azimuth, d_radius) -> (B, 4) [d_polar, sin, cos, d_radius]."""
    return torch.stack([pose[:, 0], torch.sin(pose[:, 1]), torch.cos(pose[:, 1]), pose[:, 2]], dim=-1)


def _place(module: torch.nn.Module, device: torch.device, dtype: torch.dtype) -> None:
    """Move to ``device``; cast only when the dtype differs (diffusers warns on every dtype cast)."""
    module.to(device)
    if next(module.parameters()).dtype != dtype:
        module.to(dtype)


class Zero123Predictor:
    """Zero-1-to-3 (UNet, VAE, CLIP, cc_projection) with frozen weights behind the ``NoisePredictor`` calls.

    Conditioning follows the original: the reference's CLIP image embedding and the pose features
    go through ``cc_projection`` to ONE cross-attention token; the reference's VAE latent (mode,
    unscaled) is stacked after the noisy target latent (mode x scaling factor 0.18215). Only the
    UNet, evaluated per sample, runs in ``dtype`` (autocast unless float32); VAE and CLIP (once per
    view) and the pose path (cc_projection) stay float32: on the demo model, bfloat16 there flipped
    answers that float32 got right (``bench/README.md``).
    ``max_batch`` bounds one UNet call; ``gradient_checkpointing`` trades time for memory on request.
    """

    def __init__(
        self,
        modules: Zero123Modules,
        device: str | torch.device = "auto",
        dtype: torch.dtype | None = None,
        max_batch: int = 16,
        gradient_checkpointing: bool = False,
    ):
        if max_batch < 1:
            raise ValueError(f"max_batch must be >= 1, got {max_batch}")
        self.device = resolve_device(device)
        self.dtype = resolve_dtype(dtype, self.device)
        self.max_batch = max_batch
        self.modules = modules
        modules.freeze()
        for module in (modules.vae, modules.image_encoder, modules.cc_projection):
            _place(module, self.device, torch.float32)
        _place(modules.unet, self.device, self.dtype)
        if gradient_checkpointing:
            modules.unet.enable_gradient_checkpointing()
        self.num_train_timesteps = int(modules.scheduler.config.num_train_timesteps)
        self.solver_defaults: dict = {}  # the paper's settings are Zero-1-to-3's
        self._clip_mean = torch.tensor(modules.clip_mean, device=self.device).view(1, 3, 1, 1)
        self._clip_std = torch.tensor(modules.clip_std, device=self.device).view(1, 3, 1, 1)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_pretrained(cls, path: str | Path, device: str | torch.device = "auto",
                        dtype: torch.dtype | None = None, **options) -> Zero123Predictor:
        """Load a diffusers-layout Zero-1-to-3 folder offline (raises ``ModelLoadError``)."""
        return cls(load_diffusers_folder(path), device, dtype, **options)

    @classmethod
    def from_ldm_checkpoint(cls, path: str | Path, device: str | torch.device = "auto",
                            dtype: torch.dtype | None = None, config: Zero123Config | None = None,
                            use_ema: bool = False, **options) -> Zero123Predictor:
        """Load the original single-file release (``zero123-xl.ckpt``, ``105000.ckpt``).

        ``config`` defaults to the architecture the file's tensor shapes give (``ldm_architecture``).
        """
        return cls(load_ldm_checkpoint(path, config, use_ema), device, dtype, **options)

    @classmethod
    def random(cls, config: Zero123Config, seed: int = 0, device: str | torch.device = "cpu",
               dtype: torch.dtype | None = None, **options) -> Zero123Predictor:
        """Random weights in the architecture of ``config`` (benchmarks, tests)."""
        return cls(build_modules(config, seed), device, dtype, **options)

    @classmethod
    def tiny(cls, seed: int = 0, **options) -> Zero123Predictor:
        """A tiny random Zero-1-to-3 (``Zero123Config.tiny``) on the CPU: what tests and CI run."""
        return cls.random(Zero123Config.tiny(), seed, **options)

    def save_pretrained(self, path: str | Path) -> None:
        """Write the diffusers layout (safetensors) that ``from_pretrained`` reads back."""
        save_diffusers_folder(self.modules, path)

    # ------------------------------------------------------------------ NoisePredictor
    @torch.no_grad()
    def encode(self, images: torch.Tensor) -> Views:
        """Images (N, 3, H, W) in [-1, 1] -> Views: scaled latents, reference latents, CLIP embeddings.

        ``latents`` (N, 4, H/f, W/f) = mode x scaling factor (the targets that get noised);
        ``conditioning["ref_latents"]`` the same mode unscaled; ``conditioning["image_embeds"]`` (N, P).
        """
        self._check_images(images)
        pixels = images.to(self.device, torch.float32)
        vae = self.modules.vae
        ref_latents = vae.encode(pixels).latent_dist.mode()
        embeds = self.modules.image_encoder(pixel_values=self.clip_pixels(pixels)).image_embeds
        return Views(
            latents=ref_latents * vae.config.scaling_factor,
            conditioning={"ref_latents": ref_latents, "image_embeds": embeds},
        )

    def noise_error(self, views: Views, ref: torch.Tensor, tgt: torch.Tensor, pose: torch.Tensor,
                    t: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
        """Per-sample noise MSE (B,), differentiable w.r.t. ``pose`` only; UNet calls of <= max_batch."""
        self._check_batch(views, ref, tgt, pose, t, noise)
        ref, tgt, t = (index.to(self.device, torch.long) for index in (ref, tgt, t))
        pose, noise = pose.to(self.device, torch.float32), noise.to(self.device, torch.float32)
        errors = []
        for start in range(0, len(ref), self.max_batch):
            part = slice(start, start + self.max_batch)
            noisy = self.modules.scheduler.add_noise(views.latents[tgt[part]], noise[part], t[part])
            tokens = self.pose_tokens(views.conditioning["image_embeds"][ref[part]], pose[part])
            predicted = self.predict_noise(noisy, views.conditioning["ref_latents"][ref[part]], t[part], tokens)
            errors.append((predicted.float() - noise[part]).square().mean(dim=(1, 2, 3)))
        return torch.cat(errors)

    # ------------------------------------------------------------------ building blocks
    def clip_pixels(self, images: torch.Tensor) -> torch.Tensor:
        """(N, 3, H, W) in [-1, 1] -> CLIP input (N, 3, S, S): bicubic resize, then CLIP mean/std.

        Resized like the original FrozenCLIPImageEmbedder (bicubic, align_corners, no antialias),
        normalised like CLIPImageProcessor; stays on the device.
        """
        size = self.modules.clip_size
        resized = F.interpolate(images, size=(size, size), mode="bicubic", align_corners=True)
        return ((resized + 1) / 2 - self._clip_mean) / self._clip_std

    def pose_tokens(self, image_embeds: torch.Tensor, pose: torch.Tensor) -> torch.Tensor:
        """CLIP embeddings (B, P) + poses (B, 3) -> cross-attention tokens (B, 1, D) via cc_projection (float32)."""
        features = torch.cat([image_embeds, pose_features(pose)], dim=-1).float()
        with torch.autocast(self.device.type, enabled=False):
            return self.modules.cc_projection(features)[:, None, :]

    def predict_noise(self, noisy: torch.Tensor, ref_latents: torch.Tensor, t: torch.Tensor,
                      tokens: torch.Tensor) -> torch.Tensor:
        """UNet eps for noisy target latents (B, 4, h, w) given reference latents, steps (B,), tokens (B, 1, D)."""
        with reduced_precision(self.device, self.dtype):
            return self.modules.unet(torch.cat([noisy, ref_latents], dim=1), t, encoder_hidden_states=tokens).sample

    def sample_view(self, views: Views, ref: int, pose, steps: int = 50, guidance: float = 3.0,
                    eta: float = 1.0, seed: int = 0) -> torch.Tensor:
        """Generate the view at relative ``pose`` (3,) from view ``ref``: (3, H, W) in [-1, 1] on the CPU."""
        return ddim_sample_view(self, views, ref, pose, steps=steps, guidance=guidance, eta=eta, seed=seed)

    # ------------------------------------------------------------------ checks
    def _check_images(self, images: torch.Tensor) -> None:
        factor = 2 ** (len(self.modules.vae.config.block_out_channels) - 1)
        if images.ndim != 4 or images.shape[1] != 3:
            raise ValueError(f"images must be (N, 3, H, W), got shape {tuple(images.shape)}")
        if images.shape[2] % factor or images.shape[3] % factor:
            raise ValueError(f"image height and width must be multiples of {factor}, got {tuple(images.shape[2:])}")
        if not torch.isfinite(images).all() or images.abs().max() > 1 + 1e-3:
            raise ValueError("images must be finite and in [-1, 1]")

    def _check_batch(self, views: Views, ref: torch.Tensor, tgt: torch.Tensor, pose: torch.Tensor,
                     t: torch.Tensor, noise: torch.Tensor) -> None:
        batch = len(ref)
        shapes = {"ref": (ref.shape, (batch,)), "tgt": (tgt.shape, (batch,)), "pose": (pose.shape, (batch, 3)),
                  "t": (t.shape, (batch,)), "noise": (noise.shape, (batch, *views.noise_shape))}
        for name, (got, expected) in shapes.items():
            if tuple(got) != tuple(expected):
                raise ValueError(f"{name} must have shape {tuple(expected)}, got {tuple(got)}")
        for name, index in (("ref", ref), ("tgt", tgt)):
            if batch and (index.min() < 0 or index.max() >= len(views)):
                raise ValueError(f"{name} indices must lie in [0, {len(views)}), got {index.tolist()}")
        if batch and (t.min() < 0 or t.max() >= self.num_train_timesteps):
            raise ValueError(f"t must lie in [0, {self.num_train_timesteps}), got {t.tolist()}")
