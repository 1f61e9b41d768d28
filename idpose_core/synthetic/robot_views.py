"""How a robot would report a synthetic camera: a TF chain world -> base -> camera_link -> optical, intrinsics.

The camera's optical frame (REP 103: x right, y down, z forward) hangs off ``camera_link`` (REP 103
body axes: x forward, y left, z up) by a fixed rotation; ``camera_link`` sits on an arm on a mobile
base that stands on the ground (z = 0) under the camera and faces the object at the origin. Used by
the bag writer so that ground truth has to be chained, as on a real robot. ``with_arm_error``: a camera pose
as the arm's kinematics report it, never the truth itself.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from idpose_core.cameras import pinhole_camera_matrix
from idpose_core.transforms import invert_transform

ARM_ERROR = ((0.5, 1.0), (0.002, 0.005))  # per camera: an arm's rotation (deg) and position (m) error, kinematic
# and hand-eye together, each drawn in its range
# The optical frame's axes in camera_link: x_opt = -y_link, y_opt = -z_link, z_opt = x_link.
LINK_FROM_OPTICAL = np.array([
    [0.0, 0.0, 1.0, 0.0],
    [-1.0, 0.0, 0.0, 0.0],
    [0.0, -1.0, 0.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
])


def pinhole_intrinsics(size: int, fov_deg: float) -> np.ndarray:
    """Camera matrix K (3, 3) of a square ``size`` x ``size`` image with a ``fov_deg`` field of view."""
    return pinhole_camera_matrix(size, size, fov_deg)


def robot_chain(world_from_optical: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(world_from_base, base_from_link), each (4, 4), that put the optical frame at ``world_from_optical``.

    The base stands on the ground under the camera centre, its x axis towards the object centre
    (the origin); a camera straight above the origin keeps the base at the origin facing +x.
    """
    world_from_optical = np.asarray(world_from_optical, dtype=np.float64)
    x, y = world_from_optical[:2, 3]
    yaw = math.atan2(-y, -x) if math.hypot(x, y) > 1e-9 else 0.0
    world_from_base = np.eye(4)
    world_from_base[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    world_from_base[:2, 3] = x, y
    world_from_link = world_from_optical @ invert_transform(LINK_FROM_OPTICAL)
    return world_from_base, invert_transform(world_from_base) @ world_from_link


def with_arm_error(pose: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A camera ``pose`` (4, 4) as an arm reports it: turned about a random axis and shifted in a random direction
    by amounts drawn within ``ARM_ERROR``."""
    axis, shift = rng.normal(size=3), rng.normal(size=3)
    angle, distance = math.radians(rng.uniform(*ARM_ERROR[0])), rng.uniform(*ARM_ERROR[1])
    reported = np.array(pose, dtype=np.float64)
    reported[:3, :3] = Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix() @ reported[:3, :3]
    reported[:3, 3] += shift / np.linalg.norm(shift) * distance
    return reported
