"""The reference view warped into the target view through a sphere: a geometric prior on the relative pose.

A small model trained for hours on a CPU learns slowly how a relative pose moves an object's surface across the
image when the pose only scales and shifts its features. This gives it that motion directly: the object is taken to
be a sphere of ``radius`` (in the crop's normalised coordinates, [-1, 1]) at the crop's centre, seen
orthographically, the reference camera on the equator (polar pi/2, azimuth 0; the pose is relative, so the
reference's own elevation is unknown) and the target camera at the relative pose from it. Each target pixel on the
sphere's front takes the reference's colour where that surface point faces the reference camera; the rest is
marked invisible. The warp is differentiable with respect to the pose (bilinear sampling), so the solver's
gradient reaches the pose through it too.
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F

WARP_CHANNELS = 4
"""The warp's channels: the warped reference (3, zero where invisible) and its visibility (1)."""


def camera_rotation(polar: torch.Tensor, azimuth: torch.Tensor) -> torch.Tensor:
    """Rotations (B, 3, 3) whose columns are the OpenGL axes (right, up, back) in the world of cameras at
    ``polar``, ``azimuth`` (B,) radians looking at the origin, roll-free (world up +z)."""
    sin_p, cos_p, sin_a, cos_a = torch.sin(polar), torch.cos(polar), torch.sin(azimuth), torch.cos(azimuth)
    back = torch.stack([sin_p * cos_a, sin_p * sin_a, cos_p], -1)
    up = torch.stack([-cos_p * cos_a, -cos_p * sin_a, sin_p], -1)
    right = torch.linalg.cross(up, back, dim=-1)
    return torch.stack([right, up, back], -1)


def target_to_reference(pose: torch.Tensor) -> torch.Tensor:
    """Rotations (B, 3, 3) from target to reference camera coordinates for relative poses (B, 3) =
    (d_polar, d_azimuth, d_radius), the reference camera on the equator at azimuth 0."""
    equator = torch.full_like(pose[:, 0], math.pi / 2)
    reference = camera_rotation(equator, torch.zeros_like(equator))
    target = camera_rotation(equator + pose[:, 0], pose[:, 1])
    return reference.transpose(1, 2) @ target


def sphere_warp(reference: torch.Tensor, pose: torch.Tensor, radius: float) -> torch.Tensor:
    """Reference views (B, 3, S, S) and relative poses (B, 3) -> (B, WARP_CHANNELS, S, S): the reference warped into
    each target view through a sphere of ``radius`` (channels 0-2, zero where invisible) and the visibility (3)."""
    if reference.ndim != 4 or reference.shape[1] != 3 or pose.shape != (reference.shape[0], 3):
        raise ValueError(f"need references (B, 3, S, S) and poses (B, 3), got {tuple(reference.shape)} and "
                         f"{tuple(pose.shape)}")
    batch, _, height, width = reference.shape
    device = reference.device
    u = (2 * torch.arange(width, device=device, dtype=torch.float32) + 1) / width - 1
    v = 1 - (2 * torch.arange(height, device=device, dtype=torch.float32) + 1) / height  # image rows go down
    v, u = torch.meshgrid(v, u, indexing="ij")
    depth_squared = radius ** 2 - u ** 2 - v ** 2
    on_sphere = depth_squared > 0
    front = torch.stack([u, v, torch.sqrt(depth_squared.clamp_min(0.0))], -1)  # (S, S, 3) towards the camera
    seen = torch.einsum("bij,hwj->bhwi", target_to_reference(pose.float()), front)
    visible = (on_sphere & (seen[..., 2] > 0)).to(reference.dtype)[:, None]
    grid = torch.stack([seen[..., 0], -seen[..., 1]], -1).to(reference.dtype)
    warped = F.grid_sample(reference, grid, mode="bilinear", padding_mode="border", align_corners=False)
    return torch.cat([warped * visible, visible], 1)
