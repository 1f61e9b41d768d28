"""What the direction of gravity tells about a view: its roll about the optical axis and its elevation.

Vectors are in a camera's optical frame (REP 103: x right, y down, z forward); ``up`` is the unit
vector of world up (minus gravity). An *upright* camera is the real one turned about its optical axis
until world up projects straight up in the image; that is the only kind of camera Zero-1-to-3 knows.
``roll`` is the angle of that turn: a point seen at ``p`` by the real camera is at ``rz(roll) p`` in
the upright camera's frame. The polar angle of a camera around the object (0 = straight above) is the
angle between world up and the direction from the object to the camera.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

NEAR_VERTICAL = 1e-6  # |up_x|, |up_y| below this: the camera looks straight up or down, any roll is upright


def unit(vector: np.ndarray) -> np.ndarray:
    """``vector`` (3,) scaled to length 1; ValueError for a zero or non-finite vector."""
    vector = np.asarray(vector, dtype=np.float64)
    norm = float(np.linalg.norm(vector))
    if not math.isfinite(norm) or norm < 1e-12:
        raise ValueError(f"cannot take the direction of {vector.tolist()}")
    return vector / norm


def up_from_acceleration(acceleration: np.ndarray, optical_from_imu: np.ndarray) -> np.ndarray:
    """World up (3,) in the optical frame from an accelerometer at rest.

    ``acceleration`` (3,) in the IMU frame (m/s^2): at rest it is the reaction to gravity, pointing up;
    ``optical_from_imu`` (3, 3) rotates IMU-frame vectors into the optical frame.
    """
    return unit(np.asarray(optical_from_imu, dtype=np.float64) @ np.asarray(acceleration, dtype=np.float64))


def up_from_orientation(upright_from_optical: np.ndarray) -> np.ndarray:
    """World up (3,) in the optical frame from the optical frame's orientation (3, 3) in a frame whose +z is up
    (e.g. the arm's base frame): the third row of that rotation, i.e. ``R^T (0, 0, 1)``."""
    return unit(np.asarray(upright_from_optical, dtype=np.float64).T @ np.array([0.0, 0.0, 1.0]))


def level_from_optical(up: np.ndarray) -> np.ndarray:
    """An orientation (3, 3) of the optical frame in a frame whose +z is up that carries exactly the gravity ``up``
    (its heading is arbitrary): ``up_from_orientation`` gives ``up`` back."""
    third = unit(up)
    helper = np.array([1.0, 0.0, 0.0]) if abs(third[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    first = unit(np.cross(helper, third))
    return np.stack([first, np.cross(third, first), third])


def roll_angle(up: np.ndarray) -> float:
    """The turn (radians) about the optical axis that makes the camera upright: afterwards up has no x
    component and a negative y component (it points to the top of the image). 0 when already upright."""
    x, y, _ = unit(up)
    if abs(x) < NEAR_VERTICAL and abs(y) < NEAR_VERTICAL:
        return 0.0
    return math.atan2(-x, -y)


def rz(angle: float) -> np.ndarray:
    """Rotation (3, 3) about the z axis (a camera's optical axis) by ``angle`` radians."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def polar_angle(up: np.ndarray, ray: np.ndarray = (0.0, 0.0, 1.0)) -> float:
    """The camera's polar angle (radians, 0 = above the object) given world up and the viewing ``ray`` (3,)
    from the camera towards the object centre, both in the optical frame (default: the optical axis)."""
    cosine = -float(np.dot(unit(up), unit(ray)))
    return math.acos(max(-1.0, min(1.0, cosine)))


def with_roll(upright_poses: np.ndarray, rolls: np.ndarray) -> np.ndarray:
    """Poses (N, 4, 4) of the upright cameras in the upright anchor's frame -> poses of the real cameras in the
    real anchor's frame, given each view's ``roll`` (N,): ``rz(roll_0)^T P_k rz(roll_k)``."""
    turns = np.zeros((len(rolls), 4, 4))
    turns[:, 3, 3] = 1.0
    turns[:, :3, :3] = np.stack([rz(float(roll)) for roll in rolls])
    return np.swapaxes(turns[:1], -1, -2) @ np.asarray(upright_poses, dtype=np.float64) @ turns


class GravityUnavailable(ValueError):
    """No gravity reading fits an image's stamp; the message says what was looked for."""


def resting_acceleration(stamps: np.ndarray, accelerations: np.ndarray, stamp: int, window: int,
                         tolerance: int) -> np.ndarray:
    """Mean accelerometer reading (3,) over the ``window`` before ``stamp`` (a low-pass: the robot stands
    still for the picture). Stamps are integer nanoseconds; ``stamps`` (M,), ``accelerations`` (M, 3).
    GravityUnavailable when the newest reading at or before ``stamp`` (or just after, within
    ``tolerance``) is more than ``tolerance`` away from it."""
    return np.asarray(accelerations, dtype=np.float64)[resting_window(stamps, stamp, window, tolerance)].mean(axis=0)


def resting_window(stamps: np.ndarray, stamp: int, window: int, tolerance: int) -> np.ndarray:
    """Which readings (bool (M,)) ``resting_acceleration`` averages: those of the ``window`` before ``stamp`` and
    those within ``tolerance`` of it; GravityUnavailable when none is within ``tolerance``."""
    stamps = np.asarray(stamps, dtype=np.int64)
    near = np.abs(stamps - stamp) <= tolerance
    if not near.any():
        raise GravityUnavailable(f"no IMU reading within {tolerance * 1e-9:g} s of the image stamp "
                                 f"{stamp * 1e-9:.3f} s")
    return (stamps >= stamp - window) & (stamps <= stamp) | near



IMU_WINDOW_S = 0.1  # seconds of accelerometer readings before an image averaged into its gravity


def rotation_from_extrinsic(values: Sequence[float]) -> np.ndarray:
    """An IMU-to-optical rotation (3, 3) as a user gives it: a quaternion x y z w, or roll pitch yaw in
    radians (fixed axes, applied x then y then z). ValueError naming the values for any other form."""
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 1 or len(values) not in (3, 4) or not np.all(np.isfinite(values)):
        raise ValueError(f"a rotation is a quaternion x y z w or roll pitch yaw (rad), got {values.tolist()}")
    if len(values) == 3:
        return Rotation.from_euler("xyz", values).as_matrix()  # lower case: fixed axes
    if not np.any(values):
        raise ValueError(f"the quaternion {values.tolist()} is all zero: it has no rotation")
    return Rotation.from_quat(values).as_matrix()
