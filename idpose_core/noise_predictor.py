"""The one seam between the solver and any model: the ``NoisePredictor`` protocol.

The real Zero-1-to-3, the small model trained here and test oracles all implement it, so the
solver never knows which one it inverts.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import torch


@dataclass(frozen=True)
class Views:
    """Everything per view that never changes during inversion, computed once by ``encode``.

    ``latents`` (N, C, h, w) are the clean target latents that get noised (their shape and device
    tell the solver what noise to draw); ``conditioning`` holds model-specific per-view tensors
    (embeddings, reference latents, ...), each with N first.
    """

    latents: torch.Tensor
    conditioning: dict[str, torch.Tensor] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.latents.shape[0])

    @property
    def noise_shape(self) -> tuple[int, ...]:
        """Shape of one sample's noise, (C, h, w)."""
        return tuple(self.latents.shape[1:])


@runtime_checkable
class NoisePredictor(Protocol):
    """A view-conditioned noise predictor ``f(z_t, x_ref, p, t)`` seen through two calls.

    ``num_train_timesteps`` is the length of its noise schedule; ``solver_defaults`` are the
    ``SolverConfig`` settings it recommends (e.g. the noise levels a small model was trained at),
    applied wherever the caller chose none (``SolverConfig.with_recommended``); empty for Zero-1-to-3.
    """

    num_train_timesteps: int
    solver_defaults: Mapping[str, Any]

    def encode(self, images: torch.Tensor) -> Views:
        """Images (N, 3, H, W) in [-1, 1] -> per-view ``Views``, computed once per estimate."""
        ...

    def noise_error(
        self,
        views: Views,
        ref: torch.Tensor,
        tgt: torch.Tensor,
        pose: torch.Tensor,
        t: torch.Tensor,
        noise: torch.Tensor,
    ) -> torch.Tensor:
        """Per-sample noise MSE (B,), differentiable w.r.t. ``pose``.

        Sample b conditions on view ``ref[b]`` and denoises view ``tgt[b]`` noised with
        ``noise[b]`` (C, h, w) at integer step ``t[b]`` under relative pose ``pose[b]`` =
        (d_polar, d_azimuth, d_radius) from reference to target.
        """
        ...
