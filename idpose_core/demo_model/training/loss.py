"""The training loss: the denoising error at the true relative pose, plus a ranking hinge against a wrong pose."""
from __future__ import annotations

import math

import numpy as np
import torch

from idpose_core.demo_model.model import DemoDiffusionModel

WRONG_POLAR = 0.4  # radians: how far a wrong pose of the ranking loss moves the polar angle


def wrong_poses(pose: torch.Tensor, rng: np.random.Generator) -> torch.Tensor:
    """For relative poses (B, 3), wrong ones (B, 3): the azimuth turned by 30..330 deg, the polar moved by up to
    WRONG_POLAR radians."""
    count = len(pose)
    turn = torch.as_tensor(rng.uniform(math.pi / 6, 11 * math.pi / 6, count), dtype=pose.dtype)
    tilt = torch.as_tensor(rng.uniform(-WRONG_POLAR, WRONG_POLAR, count), dtype=pose.dtype)
    return torch.stack([pose[:, 0] + tilt, torch.remainder(pose[:, 1] + turn, 2 * math.pi), pose[:, 2]], -1)


def training_loss(model: DemoDiffusionModel, reference: torch.Tensor, target: torch.Tensor, pose: torch.Tensor,
                  wrong: torch.Tensor, t: torch.Tensor, rank_weight: float, rank_margin: float
                  ) -> tuple[torch.Tensor, torch.Tensor]:
    """(total loss, denoising loss). Denoising: MSE of the UNet's output (noise or clean target, as the config's
    ``prediction_type`` says) at the true relative pose. Ranking: the same error under a ``wrong`` pose (same noise,
    same step) must exceed the true pose's by ``rank_margin`` of their sum (a hinge, weighted by ``rank_weight``):
    what the solver's inversion needs, the true pose's error the lowest."""
    noise = torch.randn_like(target)
    noisy = model.add_noise(target, noise, t)
    wanted = target if model.config.prediction_type == "sample" else noise
    embedding = model.embed(reference)
    if rank_weight == 0:
        denoising = (model.model_output(noisy, reference, embedding, pose, t) - wanted).pow(2).mean()
        return denoising, denoising
    output = model.model_output(noisy.repeat(2, 1, 1, 1), reference.repeat(2, 1, 1, 1), embedding.repeat(2, 1),
                                torch.cat([pose, wrong]), t.repeat(2))
    true_error, wrong_error = (output - wanted.repeat(2, 1, 1, 1)).pow(2).flatten(1).mean(1).chunk(2)
    gap = (wrong_error - true_error) / (wrong_error + true_error).detach()
    denoising = true_error.mean()
    return denoising + rank_weight * torch.relu(rank_margin - gap).mean(), denoising
