"""Gravity -> each view's roll and elevation, de-rolled images, and the roll put back into the poses."""
import math

import numpy as np
import pytest

from idpose_core.deroll import original_frame_mask, upright_view
from idpose_core.gravity import polar_angle, roll_angle, rz, up_from_acceleration, up_from_orientation, with_roll
from idpose_core.synthetic.robot_views import LINK_FROM_OPTICAL, pinhole_intrinsics
from idpose_core.synthetic.scenes import FOV_DEG, SceneRenderer, demo_objects, rolled_optical_frames
from idpose_core.view_input import ViewInput

SPHERES = np.array([[math.radians(p), math.radians(a), 2.0] for p, a in ((60, 30), (100, 200), (35, 300), (150, 90))])
ROLLS = np.radians([25.0, -40.0, 170.0, 0.0])
GRAVITY = 9.81


def test_roll_and_polar_come_back_exactly_from_the_up_vector():
    frames = rolled_optical_frames(SPHERES, ROLLS)
    for frame, sphere, roll in zip(frames, SPHERES, ROLLS):
        up = up_from_orientation(frame[:3, :3])
        assert roll_angle(up) == pytest.approx(roll, abs=1e-12)
        assert polar_angle(up) == pytest.approx(sphere[0], abs=1e-12)  # the camera looks at the object centre
        turned = rz(roll_angle(up)) @ up
        assert abs(turned[0]) < 1e-12 and turned[1] < 0  # upright: world up points to the top of the image


def test_the_imu_extrinsic_is_applied():
    """An IMU mounted with camera_link's axes (x forward, y left, z up): not the optical frame's."""
    optical_from_imu = np.linalg.inv(LINK_FROM_OPTICAL)[:3, :3]
    for frame in rolled_optical_frames(SPHERES, ROLLS):
        world_from_imu = frame[:3, :3] @ optical_from_imu
        at_rest = world_from_imu.T @ np.array([0.0, 0.0, GRAVITY])  # the accelerometer feels the floor's push
        np.testing.assert_allclose(up_from_acceleration(at_rest, optical_from_imu), up_from_orientation(frame[:3, :3]),
                                   atol=1e-12)
        assert not np.allclose(up_from_acceleration(at_rest, np.eye(3)), up_from_orientation(frame[:3, :3]))


def test_de_rolling_then_restoring_the_roll_gives_the_real_poses():
    real = rolled_optical_frames(SPHERES, ROLLS)
    upright = rolled_optical_frames(SPHERES, np.zeros(len(ROLLS)))
    rolls = [roll_angle(up_from_orientation(frame[:3, :3])) for frame in real]
    upright_poses = np.linalg.inv(upright[0]) @ upright
    np.testing.assert_allclose(with_roll(upright_poses, np.array(rolls)), np.linalg.inv(real[0]) @ real, atol=1e-12)
    np.testing.assert_allclose(with_roll(upright_poses, np.zeros(len(ROLLS))), upright_poses, atol=1e-15)


@pytest.mark.parametrize("roll_deg", [30.0, -75.0])
def test_a_rolled_render_turned_upright_matches_the_upright_render(roll_deg):
    size, sphere = 128, SPHERES[0]
    with SceneRenderer(demo_objects()[0], size) as renderer:
        _, upright_mask = renderer.render(*sphere)
        rgb, mask = renderer.render(*sphere, roll=math.radians(roll_deg))
    frame = rolled_optical_frames(sphere[None], np.radians([roll_deg]))[0]
    view = ViewInput(rgb, np.where(mask, 255, 0).astype(np.uint8), intrinsics=pinhole_intrinsics(size, FOV_DEG),
                     gravity_up=up_from_orientation(frame[:3, :3]))
    turned, roll = upright_view(view)
    assert roll == pytest.approx(math.radians(roll_deg), abs=1e-9)
    assert abs(turned.gravity_up[0]) < 1e-12 and turned.gravity_up[1] < 0
    cx, cy = turned.intrinsics[0, 2], turned.intrinsics[1, 2]  # the principal point keeps the image centre
    x0, y0 = int(round(cx - size / 2)), int(round(cy - size / 2))
    crop = turned.alpha[y0:y0 + size, x0:x0 + size] > 127
    assert (crop & upright_mask).sum() / (crop | upright_mask).sum() > 0.9
    assert (mask & upright_mask).sum() / (mask | upright_mask).sum() < 0.8  # the roll was visible before


def test_views_without_gravity_or_roll_stay_as_they_are():
    view = ViewInput(np.zeros((16, 16, 3), np.uint8))
    assert upright_view(view) == (view, 0.0)
    level = ViewInput(np.zeros((16, 16, 3), np.uint8), gravity_up=np.array([0.0, -1.0, 0.0]))
    turned, roll = upright_view(level)
    assert turned is level and roll == 0.0


def test_a_mask_on_the_upright_canvas_maps_back_to_the_original_pixels():
    """An object cut by the left edge of a rolled view: on the upright canvas the edge is a tilted line inside
    the canvas, and mapping the canvas mask back gives the original mask, edge and all."""
    size = 96
    mask = np.zeros((size, size), dtype=bool)
    mask[30:60, 0:20] = True
    frame = rolled_optical_frames(SPHERES[:1], np.radians([35.0]))[0]
    view = ViewInput(np.zeros((size, size, 3), np.uint8), mask=mask, intrinsics=pinhole_intrinsics(size, FOV_DEG),
                     gravity_up=up_from_orientation(frame[:3, :3]))
    turned, roll = upright_view(view)
    assert turned.mask.shape != mask.shape and not turned.mask[:, :3].any()
    back = original_frame_mask(turned.mask, view, roll)
    assert back.shape == mask.shape
    assert (back & mask).sum() / (back | mask).sum() > 0.9 and back[:, 0].any()
    level = ViewInput(view.rgb, mask=mask)
    assert original_frame_mask(mask, level, 0.0) is mask
