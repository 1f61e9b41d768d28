"""True cameras in the object's spherical frame: object centre at the origin, world up -> +z, OpenGL axes."""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from idpose_core.cameras import opengl_to_optical


def world_to_object(center: Sequence[float], up: Sequence[float]) -> np.ndarray:
    """Rigid transform (4, 4) from the world to the object frame: ``center`` -> origin, ``up`` -> +z.

    The rotation is the smallest one taking ``up`` to +z; the azimuth origin it leaves does not
    matter, since only relative poses are scored. Raises ValueError for a zero ``up``.
    """
    up = np.asarray(up, dtype=np.float64)
    if up.shape != (3,) or np.linalg.norm(up) < 1e-12:
        raise ValueError(f"the up axis must be a non-zero 3-vector, got {up.tolist()}")
    up = up / np.linalg.norm(up)
    z = np.array([0.0, 0.0, 1.0])
    axis, cosine = np.cross(up, z), float(np.dot(up, z))
    if cosine < -1.0 + 1e-12:  # up is -z: half a turn about x
        rotation = np.diag([1.0, -1.0, -1.0])
    else:
        skew = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
        rotation = np.eye(3) + skew + skew @ skew / (1.0 + cosine)
    transform = np.eye(4)
    transform[:3, :3] = rotation
    transform[:3, 3] = -rotation @ np.asarray(center, dtype=np.float64)
    return transform


def object_frame_c2w(world_from_optical: np.ndarray, center: Sequence[float], up: Sequence[float]) -> np.ndarray:
    """True cameras (..., 4, 4) in the world, optical axes -> OpenGL camera-to-world in the object frame."""
    return opengl_to_optical(world_to_object(center, up) @ np.asarray(world_from_optical, dtype=np.float64))


def world_cameras(poses: np.ndarray, anchor_c2w: np.ndarray) -> np.ndarray:
    """Estimated cameras as OpenGL camera-to-world (N, 4, 4) in the object frame: ``poses`` (N, 4, 4), optical
    frames in the anchor's optical frame (what the node publishes), placed by the anchor's true pose."""
    anchor = opengl_to_optical(np.asarray(anchor_c2w, dtype=np.float64))
    return opengl_to_optical(anchor @ np.asarray(poses, dtype=np.float64))
