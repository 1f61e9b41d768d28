"""Matching a view's other inputs by stamp: depth and masks (now or later), CameraInfo, gravity from Imu or pose."""
import math

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import QuaternionStamped, Vector3
from sensor_msgs.msg import CameraInfo, Image, Imu
from std_msgs.msg import Header

from idpose_core.gravity import up_from_orientation
from idpose_core.synthetic.robot_views import LINK_FROM_OPTICAL
from idpose_core.synthetic.scenes import rolled_optical_frames
from idpose_ros.node.input_sync import InputSync
from msg_adapters import AdapterError, matrix_to_pose

SECOND = 1_000_000_000
FRAME = rolled_optical_frames(np.array([[math.radians(70), 0.4, 0.5]]), np.radians([30.0]))[0]
OPTICAL_FROM_IMU = np.linalg.inv(LINK_FROM_OPTICAL)[:3, :3]  # an IMU with camera_link's axes


def header(stamp: int) -> Header:
    return Header(stamp=Time(sec=stamp // SECOND, nanosec=stamp % SECOND), frame_id="cam")


def imu(stamp: int, tilt: np.ndarray | None = None) -> Imu:
    world_from_imu = FRAME[:3, :3] @ OPTICAL_FROM_IMU
    a = world_from_imu.T @ np.array([0.0, 0.0, 9.81]) if tilt is None else tilt
    return Imu(header=header(stamp), linear_acceleration=Vector3(x=float(a[0]), y=float(a[1]), z=float(a[2])))


def test_gravity_from_the_accelerometer_through_a_non_identity_extrinsic():
    sync = InputSync("auto", OPTICAL_FROM_IMU, imu_window=0.1, tolerance=0.02)
    view = 10 * SECOND
    for k in range(-40, 2):  # 200 Hz around the view, one noisy reading long before the window
        sync.add_imu(imu(view + k * 5_000_000), now=view)
    sync.add_imu(imu(view - 3 * SECOND, tilt=np.array([9.81, 0.0, 0.0])), now=view)
    matched = sync.match(view, (64, 48), now=view)
    np.testing.assert_allclose(matched.gravity_up, up_from_orientation(FRAME[:3, :3]), atol=1e-9)
    assert matched.gravity_problem == "" and matched.pending == frozenset()
    late = sync.match(view + SECOND, (64, 48), now=view + SECOND)
    assert late.gravity_up is None and "no IMU reading within 0.02 s" in late.gravity_problem
    with pytest.raises(AdapterError, match="no direction"):
        sync.add_imu(imu(view, tilt=np.zeros(3)), now=view)


def test_orientation_wins_and_required_gravity_names_what_is_missing():
    sync = InputSync("required", tolerance=0.02)
    assert sync.match(SECOND, (64, 48), now=SECOND).gravity_problem == "no Imu or orientation message received"
    pose = matrix_to_pose(FRAME)
    sync.add_orientation(QuaternionStamped(header=header(SECOND + 5_000_000), quaternion=pose.orientation), now=SECOND)
    np.testing.assert_allclose(sync.match(SECOND, (64, 48), now=SECOND).gravity_up,
                               up_from_orientation(FRAME[:3, :3]), atol=1e-12)
    assert "no orientation within" in sync.match(2 * SECOND, (64, 48), now=2 * SECOND).gravity_problem
    off = InputSync("off")
    off.add_orientation(QuaternionStamped(header=header(SECOND), quaternion=pose.orientation), now=SECOND)
    assert off.match(SECOND, (64, 48), now=SECOND).gravity_up is None


def test_depth_matches_by_stamp_now_or_later_and_camera_info_by_size():
    sync = InputSync("auto", tolerance=0.02)
    depth = Image(header=header(SECOND + 10_000_000), encoding="16UC1", width=64, height=48)
    sync.add_image("depth", depth, now=SECOND)
    sync.add_camera_info(CameraInfo(width=64, height=48))
    matched = sync.match(SECOND, (64, 48), now=SECOND)
    assert matched.depth is depth and matched.camera_info is not None and matched.mask is None
    assert matched.pending == frozenset() and matched.gravity_up is None  # no gravity topic: none asked for
    later = sync.match(2 * SECOND, (32, 24), now=2 * SECOND)
    assert later.depth is None and later.pending == {"depth"} and later.camera_info is None  # other size
    arriving = Image(header=header(2 * SECOND + 15_000_000), encoding="16UC1")
    assert sync.fits("depth", arriving, 2 * SECOND) and not sync.fits("depth", arriving, 3 * SECOND)
    assert sync.match(20 * SECOND, (64, 48), now=20 * SECOND).pending == frozenset()  # the topic went quiet
