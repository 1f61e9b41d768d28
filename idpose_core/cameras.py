"""Camera poses from spherical coordinates around the object, and the frames the node publishes in.

Conventions (README "Output frame"): world up is +z and every camera looks at the object centre (the origin)
without roll. Camera-to-world matrices are ``(..., 4, 4)`` float64. The OpenGL/Blender camera axes are
x right, y up, z backwards; the ROS optical axes (REP 103) are x right, y down, z forward. Relative
spherical poses ``(d_polar, d_azimuth, d_radius)`` follow :mod:`idpose_core.spherical`.
"""
from __future__ import annotations

import numpy as np

from idpose_core.spherical import cartesian_to_spherical, compose, relative, spherical_to_cartesian

WORLD_UP = np.array([0.0, 0.0, 1.0])
# Zero-1-to-3 radius units per object distance: the middle of its training radius range [1.5, 2.2].
ZERO123_RADIUS = 1.85
# Relative to a distance: closer than this to the z axis is straight above/below; to the centre, degenerate.
_NEAR_ZERO = 1e-9
# OpenGL <-> optical: flip the camera's y and z axes (its own inverse).
_GL_TO_OPTICAL = np.diag([1.0, -1.0, -1.0, 1.0])


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def look_at_c2w(centers: np.ndarray, pole_right: np.ndarray | None = None) -> np.ndarray:
    """OpenGL camera-to-world (..., 4, 4) of cameras at ``centers`` (..., 3) looking at the origin, up +z.

    Straight above or below the object the up vector is undefined; there the camera's x axis is
    ``pole_right`` (..., 3) (horizontal unit vectors) or, by default, world +y: the limit of the
    look-at frame approached along azimuth 0. Raises ValueError for a non-finite or zero centre.
    """
    centers = np.asarray(centers, dtype=np.float64)
    if centers.shape[-1:] != (3,):
        raise ValueError(f"camera centres must have shape (..., 3), got {centers.shape}")
    if not np.all(np.isfinite(centers)):
        raise ValueError("camera centres must be finite")
    distance = np.linalg.norm(centers, axis=-1, keepdims=True)
    if np.any(distance == 0.0):
        raise ValueError("a camera centre is at the object centre: no viewing direction")
    backward = centers / distance
    right = np.cross(WORLD_UP, backward)
    at_pole = np.linalg.norm(right, axis=-1, keepdims=True) <= _NEAR_ZERO
    fallback = np.array([0.0, 1.0, 0.0]) if pole_right is None else np.asarray(pole_right, np.float64)
    right = np.where(at_pole, np.broadcast_to(fallback, right.shape), right)
    right = _unit(right)
    up = np.cross(backward, right)
    c2w = np.zeros(centers.shape[:-1] + (4, 4))
    c2w[..., :3, 0], c2w[..., :3, 1], c2w[..., :3, 2] = right, up, backward
    c2w[..., :3, 3] = centers
    c2w[..., 3, 3] = 1.0
    return c2w


def spherical_to_c2w(sph: np.ndarray) -> np.ndarray:
    """OpenGL camera-to-world (..., 4, 4) of cameras at ``(polar, azimuth, radius)`` (..., 3) looking at the origin.

    At the poles the camera keeps the orientation it has just off the pole at its azimuth.
    """
    sph = np.asarray(sph, dtype=np.float64)
    azimuth = sph[..., 1]
    pole_right = np.stack([-np.sin(azimuth), np.cos(azimuth), np.zeros_like(azimuth)], axis=-1)
    return look_at_c2w(spherical_to_cartesian(sph), pole_right=pole_right)


def opengl_to_optical(c2w: np.ndarray) -> np.ndarray:
    """Camera-to-world (..., 4, 4) with OpenGL camera axes -> optical axes (flip y and z); also the inverse."""
    return np.asarray(c2w, dtype=np.float64) @ _GL_TO_OPTICAL


def c2w_to_spherical(c2w: np.ndarray) -> np.ndarray:
    """``(polar, azimuth in [0, 2pi), radius)`` (..., 3) of the camera centre of a camera-to-world (..., 4, 4)."""
    c2w = np.asarray(c2w, dtype=np.float64)
    if c2w.shape[-2:] != (4, 4):
        raise ValueError(f"camera-to-world matrices must have shape (..., 4, 4), got {c2w.shape}")
    return cartesian_to_spherical(c2w[..., :3, 3])


def relative_spherical(anchor_c2w: np.ndarray, target_c2w: np.ndarray) -> np.ndarray:
    """Relative spherical pose (..., 3) from the anchor camera to the target camera (both (..., 4, 4))."""
    return relative(c2w_to_spherical(anchor_c2w), c2w_to_spherical(target_c2w))


def apply_relative(anchor_sph: np.ndarray, rel_sph: np.ndarray, radius_scale: float = ZERO123_RADIUS) -> np.ndarray:
    """Absolute ``(polar, azimuth, radius)`` (..., 3) of the view at ``rel_sph`` (..., 3) from the anchor.

    The relative radius is in Zero-1-to-3 units: one anchor distance is ``radius_scale`` units, as in the
    official protocol. Raises ValueError when a view would end up at or behind the object centre.
    """
    anchor_sph = np.asarray(anchor_sph, dtype=np.float64)
    rel_sph = np.asarray(rel_sph, dtype=np.float64)
    metres_per_unit = anchor_sph[..., 2:3] / radius_scale
    scale = np.concatenate([np.ones_like(metres_per_unit), np.ones_like(metres_per_unit), metres_per_unit], axis=-1)
    absolute = compose(anchor_sph, rel_sph * scale)
    if np.any(absolute[..., 2] <= _NEAR_ZERO * anchor_sph[..., 2]):
        raise ValueError("a relative radius puts a camera at or behind the object centre")
    return absolute


def pinhole_camera_matrix(width: int, height: int, fov_deg: float) -> np.ndarray:
    """Camera matrix K (3, 3) of a ``width`` x ``height`` image with a horizontal field of view of ``fov_deg``,
    square pixels and the principal point at the image centre."""
    focal = 0.5 * width / np.tan(np.radians(fov_deg) / 2.0)
    return np.array([[focal, 0.0, 0.5 * width], [0.0, focal, 0.5 * height], [0.0, 0.0, 1.0]])


def anchor_frame_poses(
    rel_sph: np.ndarray, anchor_polar: float, object_distance: float, radius_scale: float = ZERO123_RADIUS
) -> np.ndarray:
    """Optical-convention poses (N+1, 4, 4) of the anchor and N views in the anchor camera's optical frame.

    ``rel_sph`` (N, 3) are the anchor -> view relative poses; ``anchor_polar`` (rad) is the anchor's
    polar angle and ``object_distance`` (metres) its distance to the object centre, which sets the scale.
    The first pose is the identity.
    """
    rel_sph = np.asarray(rel_sph, dtype=np.float64).reshape(-1, 3)
    if not (np.all(np.isfinite(rel_sph)) and np.isfinite(anchor_polar)):
        raise ValueError("relative poses and the anchor polar angle must be finite")
    if not (np.isfinite(object_distance) and object_distance > 0.0):
        raise ValueError(f"object_distance must be a positive distance, got {object_distance}")
    anchor_sph = np.array([anchor_polar, 0.0, object_distance])
    return first_camera_frame_poses(
        np.concatenate([anchor_sph[None], apply_relative(anchor_sph, rel_sph, radius_scale)], axis=0))


def first_camera_frame_poses(spheres: np.ndarray) -> np.ndarray:
    """Optical-convention poses (N, 4, 4) of look-at cameras at absolute ``spheres`` (N, 3) = (polar, azimuth,
    radius) in the first camera's optical frame (the first pose is the identity)."""
    world_from_cams = opengl_to_optical(spherical_to_c2w(np.asarray(spheres, dtype=np.float64)))
    return np.linalg.inv(world_from_cams[0]) @ world_from_cams
