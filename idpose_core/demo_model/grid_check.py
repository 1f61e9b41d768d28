"""A cheap inversion check for any ``NoisePredictor``: grid search of the pairwise noise error.

Used while training (accuracy vs training time), in tests (the shipped model must beat random
poses) and in benchmarks; it is exploration only, without the solver's gradient refinement.
"""
from __future__ import annotations

import math

import numpy as np
import torch

from idpose_core.cameras import spherical_to_c2w
from idpose_core.metrics import pair_errors
from idpose_core.noise_predictor import NoisePredictor, Views
from idpose_core.spherical import invert


def pose_grid(azimuth_count: int, polar_offsets_deg: tuple[float, ...]) -> torch.Tensor:
    """Candidate relative poses (K, 3): every azimuth step of 360/azimuth_count x every polar offset, radius 0."""
    azimuths = torch.arange(azimuth_count, dtype=torch.float32) * (2 * math.pi / azimuth_count)
    polars = torch.tensor([math.radians(p) for p in polar_offsets_deg], dtype=torch.float32)
    grid = torch.cartesian_prod(polars, azimuths)
    return torch.cat([grid, torch.zeros(len(grid), 1)], dim=1)


@torch.no_grad()
def pairwise_errors(predictor: NoisePredictor, views: Views, ref: int, tgt: int, candidates: torch.Tensor,
                    t: int, noise: torch.Tensor, max_batch: int = 256) -> torch.Tensor:
    """``l(p; ref, tgt) + l(-p; tgt, ref)`` (K,) per candidate pose (K, 3), averaged over noise (S, C, h, w)."""
    count, samples = len(candidates), len(noise)
    poses = torch.cat([candidates, invert(candidates)]).repeat_interleave(samples, 0)
    refs = torch.tensor([ref] * count * samples + [tgt] * count * samples)
    tgts = torch.tensor([tgt] * count * samples + [ref] * count * samples)
    noises = noise.repeat(2 * count, 1, 1, 1)
    errors = torch.cat([
        predictor.noise_error(views, refs[i:i + max_batch], tgts[i:i + max_batch], poses[i:i + max_batch],
                              torch.full((len(refs[i:i + max_batch]),), t, dtype=torch.long),
                              noises[i:i + max_batch]).cpu()
        for i in range(0, len(refs), max_batch)])
    return errors.reshape(2, count, samples).mean(-1).sum(0)


def grid_search(predictor: NoisePredictor, reference: torch.Tensor, target: torch.Tensor, candidates: torch.Tensor,
                t: int, noise_samples: int, seed: int = 0) -> np.ndarray:
    """Best candidate relative pose (P, 3) for each of P pairs of images ``reference``/``target`` (P, 3, H, W)."""
    generator = torch.Generator().manual_seed(seed)
    best = []
    for index in range(len(reference)):
        views = predictor.encode(torch.stack([reference[index], target[index]]))
        noise = torch.randn((noise_samples, *views.noise_shape), generator=generator)
        errors = pairwise_errors(predictor, views, 0, 1, candidates, t, noise)
        best.append(candidates[int(torch.argmin(errors))].numpy())
    return np.stack(best).astype(np.float64)


def rotation_errors(pred_rel: np.ndarray, reference_sph: np.ndarray, target_sph: np.ndarray) -> np.ndarray:
    """Rotation errors (P,) in degrees of predicted relative poses (P, 3) given the true cameras (P, 3)."""
    rot_err, _ = pair_errors(pred_rel, spherical_to_c2w(reference_sph), spherical_to_c2w(target_sph))
    return rot_err
