"""Relative spherical poses in Zero-1-to-3's convention, for numpy arrays and torch tensors alike.

A pose is ``(..., 3)`` = ``(d_polar, d_azimuth, d_radius)`` in radians (radius in the caller's unit).
Absolute spherical coordinates ``(polar, azimuth, radius)`` use world up +z: polar 0 is straight
above the object, azimuth is measured in the xy plane from +x. Every function is elementwise over
leading dimensions and differentiable for torch inputs (``remainder`` has gradient 1).
"""
from __future__ import annotations

import math
from typing import TypeVar

import numpy as np
import torch

Array = TypeVar("Array", np.ndarray, torch.Tensor)

TWO_PI = 2.0 * math.pi


def _stack(parts: list, like: Array) -> Array:
    if isinstance(like, torch.Tensor):
        return torch.stack(parts, dim=-1)
    return np.stack(parts, axis=-1)


def _as_array(x) -> np.ndarray | torch.Tensor:
    return x if isinstance(x, torch.Tensor) else np.asarray(x, dtype=np.float64)


def wrap_azimuth(azimuth: Array) -> Array:
    """Azimuth into [0, 2pi) (a tiny negative angle's remainder rounds up to 2pi; that one wraps to ~0)."""
    if isinstance(azimuth, torch.Tensor):
        wrapped = torch.remainder(azimuth, TWO_PI)
        return torch.where(wrapped >= TWO_PI, wrapped - TWO_PI, wrapped)
    wrapped = np.mod(azimuth, TWO_PI)
    return wrapped - TWO_PI * (wrapped >= TWO_PI)


def invert(pose: Array) -> Array:
    """The reverse relative pose ``p' = -p`` (azimuth ``2pi - az`` wrapped to [0, 2pi)); (..., 3)."""
    pose = _as_array(pose)
    return _stack([-pose[..., 0], wrap_azimuth(-pose[..., 1]), -pose[..., 2]], pose)


def compose(first: Array, second: Array) -> Array:
    """Pose from a to c given a->b (``first``) and b->c (``second``): addition, azimuth mod 2pi."""
    first, second = _as_array(first), _as_array(second)
    total = first + second
    return _stack([total[..., 0], wrap_azimuth(total[..., 1]), total[..., 2]], total)


def relative(source: Array, target: Array) -> Array:
    """Relative pose from absolute spherical coordinates ``source`` to ``target``; (..., 3)."""
    source, target = _as_array(source), _as_array(target)
    delta = target - source
    return _stack([delta[..., 0], wrap_azimuth(delta[..., 1]), delta[..., 2]], delta)


def spherical_to_cartesian(sph: Array) -> Array:
    """``(polar, azimuth, radius)`` -> ``r (sin p cos a, sin p sin a, cos p)``; (..., 3) -> (..., 3)."""
    sph = _as_array(sph)
    lib = torch if isinstance(sph, torch.Tensor) else np
    polar, azimuth, radius = sph[..., 0], sph[..., 1], sph[..., 2]
    return _stack(
        [
            radius * lib.sin(polar) * lib.cos(azimuth),
            radius * lib.sin(polar) * lib.sin(azimuth),
            radius * lib.cos(polar),
        ],
        sph,
    )


def cartesian_to_spherical(xyz: Array) -> Array:
    """Point (..., 3) -> ``(polar in [0, pi], azimuth in [0, 2pi), radius)``."""
    xyz = _as_array(xyz)
    lib = torch if isinstance(xyz, torch.Tensor) else np
    x, y, z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
    radius = lib.sqrt(x * x + y * y + z * z)
    polar = lib.arctan2(lib.sqrt(x * x + y * y), z)
    azimuth = wrap_azimuth(lib.arctan2(y, x))
    return _stack([polar, azimuth, radius], xyz)
