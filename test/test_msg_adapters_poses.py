"""4x4 transforms <-> Pose / PoseArray: unit quaternions with w >= 0, exact round trips incl. 180 degrees."""
import cv2
import numpy as np
import pytest
import rclpy.time
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, Quaternion
from hypothesis import given, settings
from hypothesis import strategies as st

from msg_adapters import AdapterError, matrix_to_pose, pose_to_matrix, poses_to_pose_array

unit_axes = st.tuples(*[st.floats(-1, 1)] * 3).map(np.array).filter(lambda v: np.linalg.norm(v) > 1e-3).map(
    lambda v: v / np.linalg.norm(v))
angles = st.one_of(st.floats(0.0, np.pi), st.sampled_from([0.0, np.pi, np.pi - 1e-9, 1e-9, np.pi / 2]))
translations = st.tuples(*[st.floats(-100, 100)] * 3).map(np.array)


def transform(rotation: np.ndarray, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3], matrix[:3, 3] = rotation, translation
    return matrix


def quaternion(pose: Pose) -> np.ndarray:
    o = pose.orientation
    return np.array([o.x, o.y, o.z, o.w])


@settings(max_examples=300, deadline=None)
@given(axis=unit_axes, angle=angles, translation=translations)
def test_axis_angle_rotations_round_trip_with_the_expected_quaternion(axis, angle, translation):
    """Rotations from OpenCV's Rodrigues; the quaternion must be (sin(a/2) axis, cos(a/2)) up to the w >= 0 sign."""
    matrix = transform(cv2.Rodrigues(axis * angle)[0], translation)
    pose = matrix_to_pose(matrix)
    q = quaternion(pose)
    assert abs(np.linalg.norm(q) - 1) < 1e-12 and q[3] >= 0
    expected = np.append(np.sin(angle / 2) * axis, np.cos(angle / 2))
    assert min(np.abs(q - expected).max(), np.abs(q + expected).max()) < 1e-9
    assert np.abs(pose_to_matrix(pose) - matrix).max() < 1e-9


@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, -2, 3), (-1, -1, -1)])
def test_half_turns_round_trip_exactly_with_w_zero_and_a_canonical_sign(axis):
    n = np.asarray(axis, float) / np.linalg.norm(axis)
    half_turn = 2 * np.outer(n, n) - np.eye(3)
    pose = matrix_to_pose(transform(half_turn))
    q = quaternion(pose)
    assert abs(q[3]) < 1e-15
    assert np.abs(np.abs(q[:3]) - np.abs(n)).max() < 1e-12
    assert q[np.flatnonzero(np.abs(q[:3]) > 1e-12)[0]] > 0
    assert np.abs(pose_to_matrix(pose)[:3, :3] - half_turn).max() < 1e-9


def test_float32_transforms_are_accepted():
    matrix = transform(cv2.Rodrigues(np.array([0.3, -1.2, 0.7]))[0], (1, 2, 3)).astype(np.float32)
    assert np.abs(pose_to_matrix(matrix_to_pose(matrix)) - matrix).max() < 1e-6


def test_non_unit_quaternion_is_normalised():
    pose = Pose(position=Point(x=1.0), orientation=Quaternion(x=0.0, y=0.0, z=2.0, w=2.0))
    expected = transform(cv2.Rodrigues(np.array([0.0, 0.0, np.pi / 2]))[0], (1, 0, 0))
    assert np.abs(pose_to_matrix(pose) - expected).max() < 1e-12


def rotated_about_z(degrees: float) -> np.ndarray:
    return transform(cv2.Rodrigues(np.array([0.0, 0.0, np.radians(degrees)]))[0])


def bad(**changes) -> np.ndarray:
    """The identity transform with entries (row, col) replaced."""
    matrix = np.eye(4)
    for key, value in changes.items():
        matrix[int(key[1]), int(key[2])] = value
    return matrix


@pytest.mark.parametrize("matrix, pattern", [
    (bad(e00=np.nan), r"T has non-finite entries"),
    (bad(e13=np.inf), r"T has non-finite entries"),
    (2 * rotated_about_z(30), r"T bottom row is \[0.0, 0.0, 0.0, 2.0\]; expected \[0, 0, 0, 1\]"),
    (bad(e31=0.5), r"T bottom row"),
    (bad(e00=2.0), r"T\[:3, :3\] is not a rotation"),
    (bad(e22=-1.0), r"not a rotation .*det = -1\); expected orthonormal with det \+1"),
    (bad(e01=0.1), r"not a rotation"),
    (np.zeros((4, 4)), r"T bottom row"),
    (np.eye(3), r"T must have shape \(4, 4\), got \(3, 3\)"),
    ([["a"] * 4] * 4, r"T must be a numeric array"),
], ids=["nan", "inf", "scaled", "projective", "stretched", "reflection", "shear", "zeros", "3x3", "strings"])
def test_bad_matrix_raises_adapter_error(matrix, pattern):
    with pytest.raises(AdapterError, match=pattern):
        matrix_to_pose(matrix)


@pytest.mark.parametrize("orientation, position, pattern", [
    (Quaternion(x=0.0, y=0.0, z=0.0, w=0.0), Point(), r"Pose.orientation has zero norm"),
    (Quaternion(x=np.nan, y=0.0, z=0.0, w=1.0), Point(), r"Pose has non-finite values"),
    (Quaternion(), Point(x=np.inf), r"Pose has non-finite values"),
])
def test_bad_pose_raises_adapter_error(orientation, position, pattern):
    with pytest.raises(AdapterError, match=pattern):
        pose_to_matrix(Pose(position=position, orientation=orientation))


def test_pose_array_holds_every_transform_in_order_with_the_header():
    matrices = np.stack([rotated_about_z(deg) for deg in (0, 90, 180, 270)])
    matrices[:, :3, 3] = np.arange(12).reshape(4, 3)
    message = poses_to_pose_array(matrices, "anchor_optical", Time(sec=5, nanosec=7))
    assert message.header.frame_id == "anchor_optical"
    assert (message.header.stamp.sec, message.header.stamp.nanosec) == (5, 7)
    assert np.abs(np.stack([pose_to_matrix(p) for p in message.poses]) - matrices).max() < 1e-9


def test_pose_array_accepts_an_rclpy_time_and_zero_poses():
    message = poses_to_pose_array(np.zeros((0, 4, 4)), "anchor", rclpy.time.Time(seconds=3, nanoseconds=9))
    assert message.poses == [] and (message.header.stamp.sec, message.header.stamp.nanosec) == (3, 9)


@pytest.mark.parametrize("matrices, frame_id, stamp, pattern", [
    (np.stack([np.eye(4), np.eye(4), bad(e00=np.nan)]), "a", Time(), r"Ts\[2\] has non-finite entries"),
    (np.eye(4), "a", Time(), r"Ts must have shape \(N, 4, 4\), got \(4, 4\)"),
    (np.zeros((2, 3, 4)), "a", Time(), r"Ts must have shape \(N, 4, 4\)"),
    (np.stack([np.eye(4)]), 7, Time(), r"frame_id must be a str, got int"),
    (np.stack([np.eye(4)]), "a", 1.5, r"stamp must be a builtin_interfaces.msg.Time or rclpy Time, got float"),
])
def test_bad_pose_array_input_raises_adapter_error(matrices, frame_id, stamp, pattern):
    with pytest.raises(AdapterError, match=pattern):
        poses_to_pose_array(matrices, frame_id, stamp)
