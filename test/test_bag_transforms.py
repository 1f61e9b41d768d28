"""The TF tree of idpose_core.transforms: transforms from quaternions and back, chained lookups, interpolation,
errors."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from idpose_core.transforms import (
    TransformBuffer,
    TransformLookupError,
    interpolate_transform,
    invert_transform,
    rigid_transform,
    split_transform,
)
from msg_adapters.poses import matrix_to_pose

SECOND = 1_000_000_000


def z_rotation(angle: float) -> np.ndarray:
    """Quaternion (x, y, z, w) of a rotation by ``angle`` about +z."""
    return np.array([0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2)])


def test_quarter_turn_about_z_maps_x_to_y():
    rotation = rigid_transform([0.0, 0.0, 0.0], z_rotation(math.pi / 2))[:3, :3]
    np.testing.assert_allclose(rotation @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(rotation @ [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 1e-3))
def test_quaternion_transform_round_trip(q):
    q = np.asarray(q) / np.linalg.norm(q)
    transform = rigid_transform([1.0, 2.0, 3.0], q)
    translation, back = split_transform(transform)
    assert back[3] >= 0 and translation.tolist() == [1.0, 2.0, 3.0]
    assert min(np.abs(back - q).max(), np.abs(back + q).max()) < 1e-9  # q and -q are the same rotation
    rotation = transform[:3, :3]
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(rotation) == pytest.approx(1.0)


@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (0, -1, 1), (-1, 0, 0), (1, -2, 3)])
def test_a_half_turn_gets_the_quaternion_messages_carry(axis):
    """At w = 0, q and -q are the same half turn: /tf maths and the message adapters pick the same sign."""
    n = np.asarray(axis, float) / np.linalg.norm(axis)
    half_turn = np.eye(4)
    half_turn[:3, :3] = 2.0 * np.outer(n, n) - np.eye(3)
    _, ours = split_transform(half_turn)
    o = matrix_to_pose(half_turn).orientation
    np.testing.assert_allclose(ours, [o.x, o.y, o.z, o.w], atol=1e-12)
    assert ours[np.flatnonzero(np.abs(ours) > 1e-12)[0]] > 0


def test_zero_quaternion_is_rejected():
    with pytest.raises(ValueError, match="zero norm"):
        rigid_transform([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0])


def test_split_and_invert_transform():
    transform = rigid_transform([1.0, -2.0, 0.5], z_rotation(0.7))
    translation, quaternion = split_transform(transform)
    np.testing.assert_allclose(rigid_transform(translation, quaternion), transform, atol=1e-12)
    np.testing.assert_allclose(invert_transform(transform) @ transform, np.eye(4), atol=1e-12)


def test_interpolation_halfway_takes_the_short_arc():
    def halfway(q1: np.ndarray) -> np.ndarray:
        return interpolate_transform(0, [0.0, 0.0, 0.0], z_rotation(0.0), 2, [2.0, 0.0, 0.0], q1, 1)

    expected = rigid_transform([1.0, 0.0, 0.0], z_rotation(math.pi / 4))
    np.testing.assert_allclose(halfway(z_rotation(math.pi / 2)), expected, atol=1e-12)
    # -q is the same rotation as q: interpolation must take the short arc, not turn the long way round
    np.testing.assert_allclose(halfway(-z_rotation(math.pi / 2)), expected, atol=1e-12)


def chain_buffer() -> TransformBuffer:
    """world -> base (moving, 2 samples) -> arm (static) -> camera_optical (static)."""
    buffer = TransformBuffer()
    buffer.add("world", "base", 0, [0.0, 0.0, 0.0], z_rotation(0.0))
    buffer.add("world", "base", 2 * SECOND, [2.0, 0.0, 0.0], z_rotation(math.pi / 2))
    buffer.add("base", "arm", 0, [0.0, 0.0, 1.0], z_rotation(0.0), static=True)
    buffer.add("arm", "camera_optical", 0, [0.5, 0.0, 0.0], z_rotation(math.pi), static=True)
    return buffer


def test_chained_lookup_at_a_sample_is_the_product_of_the_links():
    buffer = chain_buffer()
    expected = (
        rigid_transform([2.0, 0.0, 0.0], z_rotation(math.pi / 2))
        @ rigid_transform([0.0, 0.0, 1.0], z_rotation(0.0))
        @ rigid_transform([0.5, 0.0, 0.0], z_rotation(math.pi))
    )
    np.testing.assert_allclose(buffer.lookup("world", "camera_optical", 2 * SECOND), expected, atol=1e-12)
    # the camera centre: base at (2,0,0) turned 90 deg, arm 1 m up, camera 0.5 m along the base's x (= world y)
    np.testing.assert_allclose(expected[:3, 3], [2.0, 0.5, 1.0], atol=1e-12)
    np.testing.assert_allclose(buffer.lookup("camera_optical", "world", 2 * SECOND), invert_transform(expected),
                               atol=1e-12)


def test_lookup_between_stamps_interpolates_the_moving_link():
    buffer = chain_buffer()
    world_from_base = buffer.lookup("world", "base", SECOND // 2)  # a quarter of the way
    np.testing.assert_allclose(world_from_base, rigid_transform([0.5, 0.0, 0.0], z_rotation(math.pi / 8)), atol=1e-12)
    world_from_camera = buffer.lookup("world", "camera_optical", SECOND)
    np.testing.assert_allclose(world_from_camera[:3, 3], [1.0 + 0.5 * math.cos(math.pi / 4),
                                                       0.5 * math.sin(math.pi / 4), 1.0], atol=1e-12)


def test_lookup_between_siblings_and_out_of_order_samples():
    buffer = TransformBuffer()
    buffer.add("world", "b", 10, [0.0, 1.0, 0.0], z_rotation(0.0))
    buffer.add("world", "a", 20, [3.0, 0.0, 0.0], z_rotation(0.0))
    buffer.add("world", "a", 0, [1.0, 0.0, 0.0], z_rotation(0.0))  # arrives late: still sorted by stamp
    buffer.add("world", "b", 0, [0.0, 1.0, 0.0], z_rotation(0.0))
    np.testing.assert_allclose(buffer.lookup("b", "a", 10)[:3, 3], [2.0, -1.0, 0.0], atol=1e-12)


def test_static_links_hold_at_any_time_and_the_latest_wins():
    buffer = TransformBuffer()
    buffer.add("world", "table", 5 * SECOND, [1.0, 0.0, 0.0], z_rotation(0.0), static=True)
    buffer.add("world", "table", 6 * SECOND, [2.0, 0.0, 0.0], z_rotation(0.0), static=True)
    np.testing.assert_allclose(buffer.lookup("world", "table", 0)[:3, 3], [2.0, 0.0, 0.0])


def test_lookup_errors_name_the_problem():
    buffer = chain_buffer()
    with pytest.raises(TransformLookupError, match="no extrapolation"):
        buffer.lookup("world", "camera_optical", 3 * SECOND)
    with pytest.raises(TransformLookupError, match=r"'camera'.*frames: arm, base, camera_optical, world"):
        buffer.lookup("world", "camera", SECOND)
    buffer.add("map", "odom", 0, [0.0, 0.0, 0.0], z_rotation(0.0), static=True)
    with pytest.raises(TransformLookupError, match="not connected"):
        buffer.lookup("world", "odom", SECOND)
    with pytest.raises(ValueError, match="two parents"):
        buffer.add("map", "base", 0, [0.0, 0.0, 0.0], z_rotation(0.0))


def test_leading_slashes_are_ignored_as_in_tf2():
    buffer = TransformBuffer()
    buffer.add("/world", "/cam", 0, [0.0, 0.0, 1.0], z_rotation(0.0), static=True)
    np.testing.assert_allclose(buffer.lookup("world", "/cam", 0)[:3, 3], [0.0, 0.0, 1.0])
