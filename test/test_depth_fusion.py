"""Depth refinement on rendered tabletop views with known cameras: a look-at diffusion pose of a camera aimed beside
the object comes back as the camera's metric 6-DoF pose; the gate keeps the diffusion pose where registration
cannot be trusted, and says why; views without depth are left alone; the fused cloud and its box.

Reduced for speed: 160 px renders of the demo lego brick (a shape whose faces fix the registration) on its table.
"""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from idpose_core.cameras import pinhole_camera_matrix
from idpose_core.depth_fusion import ObjectCloud, object_frame, refine_with_depth, view_cloud
from idpose_core.depth_fusion.refinement import RefinementSettings, gate
from idpose_core.depth_fusion.registration import Registration, register
from idpose_core.metrics import rotation_angle_deg
from idpose_core.synthetic.scenes import demo_objects
from idpose_core.synthetic.tabletop import (
    TabletopRenderer,
    _look_at,
    challenge_camera,
    random_layout,
)
from idpose_core.view_input import ViewInput

SIZE, FOV = 160, 60.0
K = pinhole_camera_matrix(SIZE, SIZE, FOV)
VOXEL = 0.005
# (polar, azimuth) in degrees and radius in m of each camera; the first two are aimed 5-7 cm beside the object.
SPHERES = np.array([[60.0, 20.0, 0.55], [50.0, 75.0, 0.6], [65.0, -40.0, 0.5]])
AIM_OFFSET = np.array([0.0, 0.06, 0.03])


def eye(sphere: np.ndarray) -> np.ndarray:
    polar, azimuth = np.radians(sphere[:2])
    return sphere[2] * np.array([math.sin(polar) * math.cos(azimuth), math.sin(polar) * math.sin(azimuth),
                                 math.cos(polar)])


@pytest.fixture(scope="module")
def scene():
    """Views, true masks, the real cameras (the first two aimed beside the object) and the look-at cameras from the
    same places, all (4, 4) optical-to-world."""
    lego = next(spec for spec in demo_objects() if spec.name == "lego")
    layout = random_layout(lego, np.random.default_rng(3), behind_azimuth=0.0)
    sphere_rad = np.column_stack([np.radians(SPHERES[:, :2]), SPHERES[:, 2]])
    look_at = [challenge_camera(sphere) for sphere in sphere_rad]
    real = [_look_at(eye(SPHERES[0]), -AIM_OFFSET), _look_at(eye(SPHERES[1]), AIM_OFFSET), look_at[2]]
    with TabletopRenderer(layout, SIZE, FOV) as renderer:
        frames = [renderer.render(camera) for camera in real]
    views = [ViewInput(rgb=frame.rgb, depth=frame.depth, intrinsics=K) for frame in frames]
    return views, [frame.target_mask for frame in frames], np.stack(real), np.stack(look_at)


def in_anchor(cameras: np.ndarray) -> np.ndarray:
    return np.linalg.inv(cameras[0]) @ cameras


def turned(pose: np.ndarray, degrees: float, axis=(1.0, 2.0, 0.5)) -> np.ndarray:
    """``pose`` with its rotation turned by ``degrees`` about ``axis`` (anchor frame), its position kept."""
    out = pose.copy()
    out[:3, :3] = Rotation.from_rotvec(np.radians(degrees) * np.asarray(axis) / np.linalg.norm(axis)).as_matrix() \
        @ pose[:3, :3]
    return out


def errors(pose: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    return rotation_angle_deg(pose[:3, :3], truth[:3, :3]), float(np.linalg.norm(pose[:3, 3] - truth[:3, 3]))


def test_a_camera_aimed_beside_the_object_gets_its_metric_pose(scene):
    views, masks, real, look_at = scene
    truth, diffusion = in_anchor(real[:2]), in_anchor(look_at[:2])
    diffusion[1] = turned(diffusion[1], 12.0)  # the diffusion estimate: a look-at camera, 12 deg off
    before = errors(diffusion[1], truth[1])
    assert before[0] > 5.0 and before[1] > 0.05, f"the look-at pose is far from the real camera: {before}"
    refined = refine_with_depth(views[:2], masks[:2], diffusion, VOXEL)
    report = refined.views[1]
    assert report.refined and report.note == "" and report.fitness >= 0.3
    rotation, translation = errors(refined.poses[1], truth[1])
    assert rotation < 1.0 and translation < 0.01, (rotation, translation)
    assert report.rotation_change_deg == pytest.approx(rotation_angle_deg(diffusion[1, :3, :3],
                                                                        refined.poses[1, :3, :3]))
    np.testing.assert_array_equal(refined.poses[0], diffusion[0])
    assert (refined.views[0].refined, refined.views[0].note) == (False, "the anchor")


def test_three_views_are_refined_together(scene):
    views, masks, real, look_at = scene
    truth, diffusion = in_anchor(real), in_anchor(look_at)
    diffusion[1:] = [turned(diffusion[1], 10.0), turned(diffusion[2], -10.0, axis=(0.0, 1.0, 1.0))]
    refined = refine_with_depth(views, masks, diffusion, VOXEL)
    assert [view.refined for view in refined.views] == [False, True, True]
    for k in (1, 2):
        rotation, translation = errors(refined.poses[k], truth[k])
        assert rotation < 1.0 and translation < 0.01, (k, rotation, translation)


def test_the_gate_keeps_the_diffusion_pose_when_registration_cannot_be_trusted(scene):
    """From a seed 150 deg off, whatever ICP finds is either a poor fit or far outside the trust region."""
    views, masks, _, look_at = scene
    diffusion = in_anchor(look_at[:2])
    diffusion[1] = turned(diffusion[1], 150.0)
    refined = refine_with_depth(views[:2], masks[:2], diffusion, VOXEL)
    report = refined.views[1]
    assert not report.refined and report.note.startswith("depth registration rejected: ")
    assert (report.rotation_change_deg, report.translation_change) == (0.0, 0.0)
    np.testing.assert_array_equal(refined.poses[1], diffusion[1])


def test_views_without_depth_keep_their_pose_and_an_anchor_without_depth_refines_nothing(scene):
    views, masks, _, look_at = scene
    diffusion = in_anchor(look_at)
    without = [views[0], ViewInput(rgb=views[1].rgb), views[2]]
    refined = refine_with_depth(without, masks, diffusion, VOXEL)
    assert (refined.views[1].refined, refined.views[1].note) == (False, "no depth on the object")
    assert math.isnan(refined.views[1].fitness)
    np.testing.assert_array_equal(refined.poses[1], diffusion[1])
    assert refined.views[2].refined
    assert refine_with_depth([ViewInput(rgb=views[0].rgb), views[1]], masks[:2], diffusion[:2], VOXEL) is None


def test_the_view_cloud_is_the_masked_depth_without_its_edge(scene):
    views, masks, real, _ = scene
    cloud = view_cloud(views[0], masks[0])
    assert 50 < len(cloud.points) < masks[0].sum(), "the eroded mask's readings"
    world = cloud.transformed(real[0]).points  # the object's centre is the world origin, its radius 10 cm
    assert np.linalg.norm(world, axis=1).max() < 0.11
    assert view_cloud(views[0], np.zeros_like(masks[0])) is None
    assert view_cloud(ViewInput(rgb=views[0].rgb), masks[0]) is None


def test_the_fused_cloud_lies_on_the_object_and_is_thinned(scene):
    views, masks, real, look_at = scene
    refined = refine_with_depth(views, masks, in_anchor(look_at), VOXEL)
    world = refined.cloud.transformed(real[0]).points
    assert np.linalg.norm(world, axis=1).max() < 0.11
    assert refined.cloud.colours.dtype == np.uint8 and refined.cloud.colours.shape == world.shape
    cells = np.unique(np.floor(refined.cloud.points / VOXEL).astype(int), axis=0)
    assert len(cells) == len(refined.cloud.points), "one point per voxel"


def test_the_object_box_follows_gravity_or_the_anchor():
    """A 20 x 10 x 5 cm box's surface, seen by a camera tilted 30 deg down: with gravity the box's sides come back
    along its own axes (z up); without, along the camera's."""
    rng = np.random.default_rng(0)
    sides = np.array([0.2, 0.1, 0.05])
    local = rng.uniform(-0.5, 0.5, (20000, 3)) * sides
    face = rng.integers(0, 3, len(local))
    local[np.arange(len(local)), face] = np.sign(rng.uniform(-1, 1, len(local))) * sides[face] / 2
    up_in_camera = np.array([0.0, -math.cos(math.radians(30)), -math.sin(math.radians(30))])
    x_level = np.array([0.0, -math.sin(math.radians(30)), math.cos(math.radians(30))])
    axes = np.stack([x_level, np.cross(up_in_camera, x_level), up_in_camera], axis=1)
    centre = np.array([0.05, 0.02, 0.6])
    cloud = ObjectCloud(local @ axes.T + centre, np.zeros(local.shape, np.uint8))
    box = object_frame(cloud, up_in_camera)
    assert box.axes_source == "gravity"
    np.testing.assert_allclose(box.pose[:3, 3], centre, atol=1e-3)
    np.testing.assert_allclose(box.pose[:3, :3], axes, atol=1e-9)
    np.testing.assert_allclose(box.size, sides, atol=2e-3)
    anchored = object_frame(cloud, None)
    assert anchored.axes_source == "anchor"
    np.testing.assert_array_equal(anchored.pose[:3, :3], np.eye(3))
    assert anchored.size[2] > sides[2] + 0.02, "along the tilted camera's axes the box looks deeper"


def test_the_gate_bounds_the_inlier_rmse_at_0_95_voxels():
    """A fit looser than 0.95 voxels (a slide along a smooth surface fits about so) keeps the seed; a tighter one
    passes; the note names the bound in mm."""
    seed, voxel = np.eye(4), 0.004
    loose = gate(Registration(seed, 0.8, 1.0 * voxel), seed, voxel, 0.5, RefinementSettings())
    assert loose == "depth registration rejected: inlier RMSE 4.0 mm > 3.8 mm"
    assert gate(Registration(seed, 0.8, 0.9 * voxel), seed, voxel, 0.5, RefinementSettings()) == ""


def test_a_fit_outside_the_trust_region_does_not_hide_one_inside_it():
    """An L-shaped block seeded 30 deg off about z: unbounded, the far matches turn it all the way home (a perfect
    fit, 30 deg from the seed); with a 10 deg trust region the best fit that stays inside it wins."""
    rng = np.random.default_rng(0)

    def box_surface(centre, sides, count):
        points = rng.uniform(-0.5, 0.5, (count, 3))
        face = rng.integers(0, 3, count)
        points[np.arange(count), face] = np.sign(points[np.arange(count), face]) * 0.5
        return np.asarray(centre) + points * np.asarray(sides)

    block = np.concatenate([box_surface([0.0, 0.0, 0.0], [0.2, 0.05, 0.05], 6000),
                            box_surface([0.075, 0.05, 0.0], [0.05, 0.1, 0.05], 3000)])
    extent = float(np.linalg.norm(np.ptp(block, axis=0)))
    seed = np.eye(4)
    seed[:3, :3] = Rotation.from_rotvec([0.0, 0.0, math.radians(30.0)]).as_matrix()
    seed[:3, 3] = block.mean(0) - seed[:3, :3] @ block.mean(0)
    free = register(block, block, seed, extent / 40, extent)
    assert rotation_angle_deg(free.transform[:3, :3], np.eye(3)) < 1.0 and free.fitness > 0.95
    bounded = register(block, block, seed, extent / 40, extent, max_turn_deg=10.0)
    assert rotation_angle_deg(bounded.transform[:3, :3], seed[:3, :3]) <= 10.0 and bounded.fitness < free.fitness
