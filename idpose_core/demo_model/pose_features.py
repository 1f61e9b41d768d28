"""The demo model's extra pose vector: Fourier features of the relative pose.

Zero-1-to-3's own 4-vector ``[d_polar, sin d_az, cos d_az, d_radius]`` (``idpose_core.zero123``'s
``pose_features``) still goes into ``cc_projection`` with the reference embedding. The Fourier
vector is this model's deviation: it is projected into the UNet's timestep embedding
(``class_embed_type="projection"``) so that the pose modulates every ResNet block instead of only
the single cross-attention token.
"""
from __future__ import annotations

import torch

FOURIER_ORDERS = (1, 2, 3)
FOURIER_DIM = 2 + 4 * len(FOURIER_ORDERS)


def fourier_pose_features(pose: torch.Tensor) -> torch.Tensor:
    """Relative pose (B, 3) -> (B, FOURIER_DIM): d_polar, d_radius, sin/cos(k d_az), sin/cos(k d_polar)."""
    d_polar, d_azimuth, d_radius = pose.unbind(-1)
    parts = [d_polar, d_radius]
    for k in FOURIER_ORDERS:
        parts += [torch.sin(k * d_azimuth), torch.cos(k * d_azimuth),
                  torch.sin(k * d_polar), torch.cos(k * d_polar)]
    return torch.stack(parts, dim=-1)
