"""Laws of relative spherical poses (idpose_core/spherical.py): round trips, inverse and composition."""
import math

import numpy as np
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from idpose_core.spherical import (
    TWO_PI,
    cartesian_to_spherical,
    compose,
    invert,
    relative,
    spherical_to_cartesian,
    wrap_azimuth,
)

finite = st.floats(-50.0, 50.0, allow_nan=False, allow_infinity=False)
poses = arrays(np.float64, (3,), elements=finite)
angles = st.floats(-4 * math.pi, 4 * math.pi, allow_nan=False)
# Polar strictly inside (0, pi) and radius > 0: where spherical coordinates are unique.
absolute = st.tuples(
    st.floats(1e-3, math.pi - 1e-3), st.floats(0.0, TWO_PI, exclude_max=True), st.floats(1e-2, 100.0)
).map(np.array)


def azimuth_gap(a, b):
    """Distance between two azimuths on the circle."""
    d = np.mod(np.asarray(a) - np.asarray(b), TWO_PI)
    return np.minimum(d, TWO_PI - d)


def assert_same_pose(a, b, atol=1e-9):
    a, b = np.asarray(a), np.asarray(b)
    np.testing.assert_allclose(a[..., [0, 2]], b[..., [0, 2]], atol=atol)
    assert np.all(azimuth_gap(a[..., 1], b[..., 1]) < atol)


@given(angles)
def test_wrap_azimuth_lands_in_half_open_circle(azimuth):
    for value in (wrap_azimuth(np.float64(azimuth)), wrap_azimuth(torch.tensor(azimuth, dtype=torch.float64))):
        assert 0.0 <= float(value) < TWO_PI
        assert azimuth_gap(float(value), azimuth) < 1e-9


def test_wrap_azimuth_of_a_tiny_negative_angle_is_below_two_pi():
    """-1e-17 mod 2pi rounds to 2pi in floating point; the wrap must still stay in [0, 2pi)."""
    assert float(wrap_azimuth(np.float64(-1e-17))) < TWO_PI
    assert float(wrap_azimuth(torch.tensor(-1e-17, dtype=torch.float64))) < TWO_PI
    assert float(wrap_azimuth(torch.tensor(-1e-9, dtype=torch.float32))) < TWO_PI


@given(absolute)
def test_spherical_cartesian_spherical_round_trip(sph):
    assert_same_pose(cartesian_to_spherical(spherical_to_cartesian(sph)), sph, atol=1e-7)


@given(arrays(np.float64, (3,), elements=finite).filter(lambda p: np.linalg.norm(p) > 1e-3))
def test_cartesian_spherical_cartesian_round_trip(xyz):
    np.testing.assert_allclose(spherical_to_cartesian(cartesian_to_spherical(xyz)), xyz, atol=1e-9)


def test_spherical_to_cartesian_axes():
    """Polar 0 is straight above (+z); azimuth 0 and pi/2 on the equator are +x and +y."""
    sph = np.array([[0.0, 1.0, 2.0], [math.pi / 2, 0.0, 2.0], [math.pi / 2, math.pi / 2, 2.0], [math.pi, 0.0, 2.0]])
    expected = np.array([[0, 0, 2], [2, 0, 0], [0, 2, 0], [0, 0, -2]], dtype=float)
    np.testing.assert_allclose(spherical_to_cartesian(sph), expected, atol=1e-12)


@given(poses)
def test_invert_is_an_involution(pose):
    assert_same_pose(invert(invert(pose)), pose)


@given(poses)
def test_pose_composed_with_its_inverse_is_zero(pose):
    assert_same_pose(compose(pose, invert(pose)), np.zeros(3))
    assert_same_pose(compose(invert(pose), pose), np.zeros(3))


@given(poses, poses, poses)
def test_compose_is_associative(a, b, c):
    assert_same_pose(compose(compose(a, b), c), compose(a, compose(b, c)), atol=1e-9)


@given(poses, poses)
def test_inverse_of_a_composition_reverses_the_order(a, b):
    assert_same_pose(invert(compose(a, b)), compose(invert(b), invert(a)), atol=1e-9)


@given(absolute, absolute)
def test_relative_pose_takes_source_to_target(source, target):
    rel = relative(source, target)
    assert 0.0 <= rel[1] < TWO_PI
    assert_same_pose(compose(source, rel), target, atol=1e-9)
    assert_same_pose(relative(target, source), invert(rel), atol=1e-9)


@given(absolute, absolute, absolute)
def test_relative_poses_chain_through_a_middle_view(a, b, c):
    """The identity behind the triangular error: p_ab + p_bc = p_ac."""
    assert_same_pose(compose(relative(a, b), relative(b, c)), relative(a, c), atol=1e-9)


@settings(max_examples=30)
@given(arrays(np.float64, (5, 3), elements=finite), arrays(np.float64, (5, 3), elements=finite))
def test_torch_and_numpy_agree_batched(first, second):
    t_first, t_second = torch.from_numpy(first), torch.from_numpy(second)
    np.testing.assert_allclose(invert(t_first).numpy(), invert(first), atol=1e-12)
    np.testing.assert_allclose(compose(t_first, t_second).numpy(), compose(first, second), atol=1e-12)
    np.testing.assert_allclose(relative(t_first, t_second).numpy(), relative(first, second), atol=1e-12)
    np.testing.assert_allclose(spherical_to_cartesian(t_first).numpy(), spherical_to_cartesian(first), atol=1e-9)


def test_torch_gradients_flow_through_composition_and_inverse():
    """The solver differentiates p'_i + p_j: every component must pass gradient 1 or -1."""
    p_i = torch.tensor([0.1, 5.0, 0.2], dtype=torch.float64, requires_grad=True)
    p_j = torch.tensor([-0.3, 2.0, 0.1], dtype=torch.float64, requires_grad=True)
    compose(invert(p_i), p_j).sum().backward()
    np.testing.assert_allclose(p_i.grad.numpy(), [-1.0, -1.0, -1.0])
    np.testing.assert_allclose(p_j.grad.numpy(), [1.0, 1.0, 1.0])
