"""The two quaternion codes (msg_adapters for messages, idpose_core.transforms for /tf maths) write the same
numbers: the same sign convention, also for half turns, where w = 0 and either sign is the same rotation."""
import math

import numpy as np
import pytest

from idpose_core.transforms import matrix_to_quaternion, quaternion_to_matrix
from msg_adapters.quaternions import quaternion_to_rotation, rotation_to_quaternion

HALF_TURN_AXES = [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (0, -1, 1), (-1, 0, 0), (0, 0, -1), (1, -2, 3),
                  (-1, 2, 3), (-2, 1, 0)]


def rotations():
    """Half turns about several axes (w = 0), a quarter turn, the identity and random rotations."""
    for axis in HALF_TURN_AXES:
        a = np.asarray(axis, float) / np.linalg.norm(axis)
        yield 2.0 * np.outer(a, a) - np.eye(3)
    yield np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    yield np.eye(3)
    rng = np.random.default_rng(0)
    for _ in range(50):
        q = rng.normal(size=4)
        yield quaternion_to_rotation(q)


@pytest.mark.parametrize("rotation", list(rotations()))
def test_both_layers_give_the_same_quaternion(rotation):
    ours, messages = matrix_to_quaternion(rotation), rotation_to_quaternion(rotation)
    np.testing.assert_allclose(ours, messages, atol=1e-12)
    np.testing.assert_allclose(quaternion_to_matrix(ours), rotation, atol=1e-12)
    np.testing.assert_allclose(quaternion_to_rotation(messages), rotation, atol=1e-12)


def test_a_half_turn_is_signed_by_its_first_non_zero_component():
    about_minus_x = np.diag([1.0, -1.0, -1.0])  # a half turn about x is one about -x
    np.testing.assert_allclose(matrix_to_quaternion(about_minus_x), [1.0, 0.0, 0.0, 0.0], atol=1e-12)
    about_y_minus_z = quaternion_to_rotation([0.0, math.sqrt(0.5), -math.sqrt(0.5), 0.0])
    np.testing.assert_allclose(matrix_to_quaternion(about_y_minus_z), [0.0, math.sqrt(0.5), -math.sqrt(0.5), 0.0],
                               atol=1e-12)
