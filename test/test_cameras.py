"""Camera poses from spherical coordinates, the optical convention and the published anchor-frame poses."""
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from idpose_core.cameras import (
    anchor_frame_poses,
    c2w_to_spherical,
    look_at_c2w,
    opengl_to_optical,
    relative_spherical,
    spherical_to_c2w,
)
from idpose_core.spherical import TWO_PI, spherical_to_cartesian

REFERENCE = Path(__file__).resolve().parents[2] / "shared" / "reference" / "idpose-official"

# Polar inside (0, pi), azimuth in [0, 2pi), radius > 0: where spherical coordinates are unique.
spheres = st.tuples(
    st.floats(1e-3, math.pi - 1e-3), st.floats(0.0, TWO_PI, exclude_max=True), st.floats(0.1, 20.0)
).map(np.array)
rel_poses = st.tuples(
    st.floats(-0.8, 0.8), st.floats(0.0, TWO_PI, exclude_max=True), st.floats(-0.5, 0.5)
).map(np.array)
POLES = np.array([[0.0, 0.0, 3.0], [0.0, 0.0, -3.0]])


def assert_valid_camera(c2w, atol=1e-9):
    """Rotation orthonormal with det +1, bottom row (0, 0, 0, 1), finite, -z (OpenGL forward) at the origin."""
    rot, centre = c2w[..., :3, :3], c2w[..., :3, 3]
    assert np.all(np.isfinite(c2w))
    np.testing.assert_allclose(rot @ np.swapaxes(rot, -1, -2), np.broadcast_to(np.eye(3), rot.shape), atol=atol)
    np.testing.assert_allclose(np.linalg.det(rot), 1.0, atol=atol)
    np.testing.assert_allclose(c2w[..., 3, :], np.broadcast_to([0, 0, 0, 1.0], centre.shape[:-1] + (4,)))
    forward = -rot[..., :, 2]
    np.testing.assert_allclose(forward, -centre / np.linalg.norm(centre, axis=-1, keepdims=True), atol=atol)


def test_camera_on_the_x_axis_has_right_y_and_up_z():
    """Looking along -x with +z up, the image's right is world +y and its up is world +z."""
    c2w = look_at_c2w(np.array([2.0, 0.0, 0.0]))
    np.testing.assert_allclose(c2w[:3, 0], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(c2w[:3, 1], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(c2w[:3, 2], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(c2w[:3, 3], [2, 0, 0])


@given(spheres)
def test_look_at_is_upright_without_roll(sph):
    c2w = spherical_to_c2w(sph)
    assert_valid_camera(c2w)
    np.testing.assert_allclose(c2w[2, 0], 0.0, atol=1e-9)  # x axis horizontal: no roll
    assert c2w[2, 1] > 0.0  # image up has a world-up component


@given(spheres)
def test_spherical_matrix_spherical_round_trip(sph):
    back = c2w_to_spherical(spherical_to_c2w(sph))
    np.testing.assert_allclose(back[[0, 2]], sph[[0, 2]], atol=1e-9)
    gap = abs(back[1] - sph[1]) % TWO_PI
    assert min(gap, TWO_PI - gap) < 1e-9


def test_look_at_is_valid_straight_above_and_below():
    c2w = look_at_c2w(POLES)
    assert_valid_camera(c2w)
    # Deterministic fallback: image right is world +y at both poles (the azimuth-0 limit).
    np.testing.assert_allclose(c2w[:, :3, 0], [[0, 1, 0], [0, 1, 0]], atol=1e-12)
    np.testing.assert_array_equal(look_at_c2w(POLES), c2w)


@pytest.mark.parametrize("polar", [0.0, math.pi])
@pytest.mark.parametrize("azimuth", [0.0, 1.0, 4.0])
def test_spherical_pose_at_a_pole_is_the_limit_along_its_azimuth(polar, azimuth):
    at_pole = spherical_to_c2w(np.array([polar, azimuth, 2.0]))
    assert_valid_camera(at_pole)
    nearby = spherical_to_c2w(np.array([abs(polar - 1e-7), azimuth, 2.0]))
    np.testing.assert_allclose(at_pole, nearby, atol=1e-6)


@pytest.mark.parametrize("bad", [np.zeros(3), np.array([np.nan, 0.0, 1.0]), np.ones(4)])
def test_look_at_rejects_degenerate_centres(bad):
    with pytest.raises(ValueError):
        look_at_c2w(bad)


def test_opengl_to_optical_flips_y_and_z_and_is_its_own_inverse():
    gl = spherical_to_c2w(np.array([math.pi / 2, 0.3, 2.0]))
    optical = opengl_to_optical(gl)
    np.testing.assert_allclose(optical[:3, 0], gl[:3, 0])
    np.testing.assert_allclose(optical[:3, 1:3], -gl[:3, 1:3])
    np.testing.assert_allclose(optical[:3, 3], gl[:3, 3])
    np.testing.assert_allclose(opengl_to_optical(optical), gl)
    # Optical z (forward) points at the object, optical y (down) points down on the equator.
    np.testing.assert_allclose(optical[:3, 2], -gl[:3, 3] / 2.0, atol=1e-12)
    assert optical[2, 1] < 0


def test_reference_poses_are_look_at_cameras():
    """The official ground truth (OpenGL axes, up +z) is reproduced by look_at from its camera centres."""
    files = sorted(REFERENCE.glob("data/omni3d/*/poses/*.npy"))
    if not files:
        pytest.skip(f"official reference data not found at {REFERENCE}")
    for file in files:
        truth = np.load(file)
        np.testing.assert_allclose(look_at_c2w(truth[:3, 3]), truth, atol=1e-6, err_msg=str(file))


def test_relative_spherical_between_matrices():
    anchor, target = np.array([1.2, 5.9, 2.0]), np.array([0.9, 0.4, 2.5])
    rel = relative_spherical(spherical_to_c2w(anchor), spherical_to_c2w(target))
    np.testing.assert_allclose(rel, [0.9 - 1.2, 0.4 - 5.9 + TWO_PI, 0.5], atol=1e-12)


def test_anchor_frame_opposite_camera_on_the_equator():
    """Azimuth pi from an equatorial anchor: at (0, 0, 2r), turned 180 degrees about the optical y axis."""
    poses = anchor_frame_poses(np.array([[0.0, math.pi, 0.0]]), anchor_polar=math.pi / 2, object_distance=0.7)
    assert poses.shape == (2, 4, 4)
    np.testing.assert_allclose(poses[0], np.eye(4), atol=1e-12)
    np.testing.assert_allclose(poses[1][:3, 3], [0, 0, 1.4], atol=1e-12)
    np.testing.assert_allclose(poses[1][:3, :3], np.diag([-1.0, 1.0, -1.0]), atol=1e-12)


def test_anchor_frame_relative_radius_is_in_zero123_units():
    """A relative radius of 1.85 units doubles the distance: the camera moves one anchor distance back."""
    poses = anchor_frame_poses(np.array([[0.0, 0.0, 1.85]]), anchor_polar=1.0, object_distance=0.5)
    np.testing.assert_allclose(poses[1], [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -0.5], [0, 0, 0, 1]], atol=1e-12)


@given(st.floats(0.05, math.pi - 0.05), st.floats(0.0, TWO_PI), st.lists(rel_poses, min_size=1, max_size=4))
def test_anchor_frame_poses_give_back_the_spherical_cameras(anchor_polar, anchor_azimuth, rels):
    """Put the anchor at any azimuth of the world: the published poses give back every view's sphere point."""
    distance = 0.8
    poses = anchor_frame_poses(np.array(rels), anchor_polar, distance)
    object_at_origin = np.eye(4)
    object_at_origin[2, 3] = -distance  # the object sits at (0, 0, distance) in the anchor optical frame
    assert_valid_camera(opengl_to_optical(object_at_origin @ poses))
    world_from_anchor = opengl_to_optical(spherical_to_c2w(np.array([anchor_polar, anchor_azimuth, distance])))
    world_cams = opengl_to_optical(world_from_anchor @ poses)
    for rel, cam in zip(rels, world_cams[1:]):
        expected = np.array([anchor_polar, anchor_azimuth, distance]) + rel * [1, 1, distance / 1.85]
        np.testing.assert_allclose(cam[:3, 3], spherical_to_cartesian(expected), atol=1e-9)
        np.testing.assert_allclose(cam[2, 0], 0.0, atol=1e-9)  # still no roll w.r.t. world up


@pytest.mark.parametrize("anchor_polar", [0.0, math.pi])
def test_anchor_frame_poses_from_straight_above_or_below(anchor_polar):
    poses = anchor_frame_poses(np.array([[0.3, 1.0, 0.0], [0.0, 2.0, 0.0]]), anchor_polar, object_distance=1.0)
    object_at_origin = np.eye(4)
    object_at_origin[2, 3] = -1.0
    assert_valid_camera(opengl_to_optical(object_at_origin @ poses))
    # Azimuth +2 at the pole: the same place, turned 2 rad about world +z, which is optical -z looking
    # down from above and optical +z looking up from below.
    np.testing.assert_allclose(poses[2][:3, 3], 0.0, atol=1e-12)
    expected = -2.0 if anchor_polar == 0.0 else 2.0
    np.testing.assert_allclose(rotation_about_optical_axis(poses[2]), expected, atol=1e-9)


def rotation_about_optical_axis(pose):
    """Signed angle (rad) of a pose rotated only about its optical z axis."""
    return math.atan2(pose[1, 0], pose[0, 0])


@pytest.mark.parametrize(
    "rel, polar, distance",
    [
        ([[0.0, 0.0, -1.85]], 1.0, 1.0),
        ([[0.0, 0.0, -2.5]], 1.0, 1.0),
        ([[np.nan, 0.0, 0.0]], 1.0, 1.0),
        ([[0.0, 0.0, 0.0]], 1.0, 0.0),
    ],
)
def test_anchor_frame_poses_reject_bad_input(rel, polar, distance):
    with pytest.raises(ValueError):
        anchor_frame_poses(np.array(rel), polar, distance)
