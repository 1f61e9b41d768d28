"""``RenderOracle``: a TEST AND BENCHMARK FIXTURE, a noise predictor that knows the scene.

It is not a model. For one synthetic object it pre-renders views on a fine (polar, azimuth) grid at
the latent resolution, interpolates that grid differentiably (bilinear, azimuth wrapping), and
answers ``noise_error`` as the ideal denoiser would if the target view were exactly the render at
``reference pose + p``: predicted noise ``(z_t - sqrt(abar) I(ref + p)) / sqrt(1 - abar)``, scored by
MSE against the true noise. Its global minimum is the true relative pose and symmetric objects give
it real local minima, so it exercises exploration, selection and refinement of the solver honestly.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from functools import lru_cache
from types import MappingProxyType
from typing import Any

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from diffusers import DDPMScheduler

from idpose_core.noise_predictor import Views
from idpose_core.spherical import TWO_PI, compose
from idpose_core.synthetic.scenes import CAMERA_RADIUS, ObjectSpec, SceneRenderer

NUM_TRAIN_TIMESTEPS = 1000

# Solver settings that suit the oracle: its error is far steeper than Zero-1-to-3's (gradients of
# ~0.5 per radian near the optimum, so the paper's lr 10 / 1 would jump tens of degrees per step),
# and its error does not depend on the noise draw (the noise cancels), so one probe noise suffices.
ORACLE_SOLVER_SETTINGS = {"adjust_lr": 0.2, "refine_lr": 0.02, "probe_batch": 1}


def scaled_linear_alphas_cumprod() -> torch.Tensor:
    """Zero-1-to-3's schedule: ``abar_t`` (1000,) for betas linear in sqrt space, 0.00085..0.012."""
    scheduler = DDPMScheduler(num_train_timesteps=NUM_TRAIN_TIMESTEPS, beta_start=0.00085,
                              beta_end=0.012, beta_schedule="scaled_linear")
    return scheduler.alphas_cumprod.to(torch.float32)


@lru_cache(maxsize=16)
def render_grid(spec: ObjectSpec, step_deg: float, latent_size: int, render_size: int) -> torch.Tensor:
    """Renders on the (polar, azimuth) grid, (P, A, 3, s, s) float32 in [-1, 1]; cached per object.

    Polar runs over [0, 180] deg and azimuth over [0, 360) deg in ``step_deg`` steps, at fixed
    radius; each render is area-downsampled from ``render_size`` to ``latent_size`` pixels.
    """
    polars = np.radians(np.arange(0.0, 180.0 + 1e-9, step_deg))
    azimuths = np.radians(np.arange(0.0, 360.0 - 1e-9, step_deg))
    grid = np.empty((len(polars), len(azimuths), latent_size, latent_size, 3), dtype=np.float32)
    with SceneRenderer(spec, image_size=render_size) as renderer:
        for row, polar in enumerate(polars):
            for col, azimuth in enumerate(azimuths):
                rgb, _ = renderer.render(polar, azimuth, CAMERA_RADIUS)
                grid[row, col] = cv2.resize(rgb, (latent_size, latent_size), interpolation=cv2.INTER_AREA)
    return torch.from_numpy(grid).permute(0, 1, 4, 2, 3) / 127.5 - 1.0


class RenderOracle:
    """Test/benchmark fixture implementing ``NoisePredictor`` with the ideal denoiser of one scene.

    ``views_sph`` (N, 3) are the TRUE absolute spherical poses (polar, azimuth, radius) of the N views
    the solver will be given, in order: ``encode`` maps image k to the grid render at pose k (the
    pixels themselves are only checked for shape). The relative radius is ignored (fixed radius).
    """

    num_train_timesteps = NUM_TRAIN_TIMESTEPS
    solver_defaults: Mapping[str, Any] = MappingProxyType({})  # tests choose (ORACLE_SOLVER_SETTINGS)

    def __init__(self, spec: ObjectSpec, views_sph: np.ndarray, step_deg: float = 5.0,
                 latent_size: int = 32, render_size: int = 64):
        views_sph = np.asarray(views_sph, dtype=np.float64)
        if views_sph.ndim != 2 or views_sph.shape[1] != 3:
            raise ValueError(f"views_sph must be (N, 3), got shape {views_sph.shape}")
        if not 0.0 < step_deg <= 45.0 or (180.0 / step_deg) % 1 or (360.0 / step_deg) % 1:
            raise ValueError(f"step_deg must divide 180 and lie in (0, 45], got {step_deg}")
        self.spec = spec
        self.views_sph = torch.as_tensor(views_sph, dtype=torch.float32)
        grid = render_grid(spec, float(step_deg), int(latent_size), int(render_size))
        polar_count, azimuth_count = grid.shape[:2]
        wrapped = torch.cat([grid, grid[:, :1]], dim=1)  # azimuth 360 deg = azimuth 0
        self._grid = wrapped.reshape(polar_count, azimuth_count + 1, -1).permute(2, 0, 1)[None]
        self._image_shape = tuple(grid.shape[2:])
        self._alphas_cumprod = scaled_linear_alphas_cumprod()

    def images(self, sph: torch.Tensor) -> torch.Tensor:
        """Interpolated renders at absolute poses ``sph`` (B, 3) -> (B, 3, s, s), differentiable.

        A polar angle outside [0, pi] is taken as the same camera position reflected over the pole.
        """
        polar = torch.remainder(sph[:, 0], TWO_PI)
        beyond = polar > math.pi
        polar = torch.where(beyond, TWO_PI - polar, polar)
        azimuth = torch.remainder(sph[:, 1] + beyond.to(sph.dtype) * math.pi, TWO_PI)
        x = azimuth / math.pi - 1.0  # [0, 2pi] -> [-1, 1] across the wrapped columns
        y = polar * (2.0 / math.pi) - 1.0  # [0, pi] -> [-1, 1] across the rows
        points = torch.stack([x, y], dim=-1)[None, None]  # (1, 1, B, 2)
        sampled = F.grid_sample(self._grid.to(sph.dtype), points, mode="bilinear",
                                padding_mode="border", align_corners=True)  # (1, D, 1, B)
        return sampled[0, :, 0].T.reshape(-1, *self._image_shape)

    def encode(self, images: torch.Tensor) -> Views:
        """Images (N, 3, H, W) of the N known views -> their grid renders as latents (N, 3, s, s)."""
        if images.ndim != 4 or images.shape[0] != len(self.views_sph) or images.shape[1] != 3:
            raise ValueError(f"expected images (N={len(self.views_sph)}, 3, H, W) for the oracle's views, "
                             f"got {tuple(images.shape)}")
        with torch.no_grad():
            latents = self.images(self.views_sph).to(images.dtype)
        return Views(latents=latents, conditioning={"view_sph": self.views_sph.to(images.dtype)})

    def noise_error(self, views: Views, ref: torch.Tensor, tgt: torch.Tensor, pose: torch.Tensor,
                    t: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
        """Ideal-denoiser noise MSE (B,) for target ``tgt`` predicted from ``ref`` under ``pose``."""
        abar = self._alphas_cumprod.to(noise.dtype)[t.long()].view(-1, 1, 1, 1)
        clean = views.latents[tgt]
        noisy = abar.sqrt() * clean + (1.0 - abar).sqrt() * noise
        predicted_view = self.images(compose(views.conditioning["view_sph"][ref], pose))
        predicted_noise = (noisy - abar.sqrt() * predicted_view) / (1.0 - abar).sqrt()
        return (predicted_noise - noise).pow(2).mean(dim=(1, 2, 3))


def thumbnail(rgb: np.ndarray) -> np.ndarray:
    """The object's bounding box (non-white pixels) of a view on white, resized to 16 x 16: the same at any zoom."""
    ys, xs = np.nonzero(np.any(rgb < 250, axis=-1))
    crop = rgb[ys.min():ys.max() + 1, xs.min():xs.max() + 1]
    return cv2.resize(crop, (16, 16), interpolation=cv2.INTER_AREA).astype(np.float32)


class IdentifyingOracle:
    """A TEST FIXTURE for evaluating bags: the ``RenderOracle`` of whichever known cameras (upright, at
    ``cameras_sph`` (K, 3)) the incoming preprocessed views were rendered from, told apart by thumbnails.

    The cameras come from the bag's seed, not from its ground truth, so a perfect score also checks the
    ground truth a bag reader finds. ``identified`` lists each estimate's view ids; ValueError when a
    view looks like none of the cameras, or like two of them.
    """

    num_train_timesteps = NUM_TRAIN_TIMESTEPS
    solver_defaults: Mapping[str, Any] = MappingProxyType({})

    def __init__(self, spec: ObjectSpec, cameras_sph: np.ndarray, size: int):
        self.spec, self.cameras_sph = spec, np.asarray(cameras_sph, dtype=np.float64)
        with SceneRenderer(spec, image_size=size) as renderer:
            self.thumbnails = np.stack([thumbnail(renderer.render(*sph)[0]) for sph in self.cameras_sph])
        self.oracle: RenderOracle | None = None
        self.identified: list[list[int]] = []

    def encode(self, images: torch.Tensor) -> Views:
        rgbs = ((images.permute(0, 2, 3, 1).numpy() + 1.0) * 127.5).round().astype(np.uint8)
        distances = [np.abs(self.thumbnails - thumbnail(rgb)).mean(axis=(1, 2, 3)) for rgb in rgbs]
        if not all(np.sort(d)[1] > 2 * d.min() for d in distances):
            raise ValueError("ambiguous view identification: a view looks like two of the known cameras")
        ids = [int(np.argmin(d)) for d in distances]
        self.identified.append(ids)
        self.oracle = RenderOracle(self.spec, self.cameras_sph[ids], step_deg=15.0)
        return self.oracle.encode(images)

    def noise_error(self, views: Views, ref: torch.Tensor, tgt: torch.Tensor, pose: torch.Tensor, t: torch.Tensor,
                    noise: torch.Tensor) -> torch.Tensor:
        return self.oracle.noise_error(views, ref, tgt, pose, t, noise)
