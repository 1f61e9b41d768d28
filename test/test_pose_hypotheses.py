"""Pose hypotheses and their verifier on rendered tabletop views with known cameras: the verifier prefers the true
pose to a turned one, gravity's yaw search holds the truth, the verifier's choice comes back without any diffusion
seed, the arm's pose is kept and a moved object is flagged, views without usable depth keep their diffusion pose
and say why, and an anchor without depth leaves the poses to the diffusion estimate.

Reduced for speed: 160 px renders of the demo lego brick on its table, three cameras 25-50 deg apart.
"""
import dataclasses
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from idpose_core.cameras import pinhole_camera_matrix
from idpose_core.depth_fusion import view_cloud
from idpose_core.metrics import rotation_angle_deg
from idpose_core.pose_hypotheses import Source, VerificationSettings, verify_with_depth
from idpose_core.pose_hypotheses.hypothesis import same_pose
from idpose_core.pose_hypotheses.pair import ARM_PRIOR, ARM_TOLERANCE_DEG, DIFFUSION_TOLERANCE_DEG, Priors
from idpose_core.pose_hypotheses.sources import arm_hypotheses, arm_pose, gravity_hypotheses
from idpose_core.pose_hypotheses.verifier import nearest_reading, one_way, verify, view_evidence
from idpose_core.segmentation import backproject, object_centre
from idpose_core.synthetic.scenes import demo_objects
from idpose_core.synthetic.tabletop import TabletopRenderer, challenge_camera, random_layout
from idpose_core.view_input import ViewInput

SIZE, FOV = 160, 60.0
K = pinhole_camera_matrix(SIZE, SIZE, FOV)
SPHERES_DEG = np.array([[60.0, 20.0, 0.55], [55.0, 45.0, 0.6], [65.0, 70.0, 0.5]])  # polar, azimuth, radius
MOVED_DEG = 60.0  # the object's turn before the moved view is taken


def render(layout, cameras):
    with TabletopRenderer(layout, SIZE, FOV) as renderer:
        return [renderer.render(camera) for camera in cameras]


@pytest.fixture(scope="module")
def scene():
    """Views with depth, gravity and the arm's exact poses; their true masks; the cameras (optical-to-world); and
    the second view again with the object turned ``MOVED_DEG`` about the vertical."""
    lego = next(spec for spec in demo_objects() if spec.name == "lego")
    layout = random_layout(lego, np.random.default_rng(3), behind_azimuth=0.0)
    spheres = np.column_stack([np.radians(SPHERES_DEG[:, :2]), SPHERES_DEG[:, 2]])
    cameras = np.stack([challenge_camera(sphere) for sphere in spheres])
    frames = render(layout, cameras)
    moved_layout = dataclasses.replace(layout, target=dataclasses.replace(
        layout.target, yaw_deg=layout.target.yaw_deg + MOVED_DEG))
    moved = render(moved_layout, cameras[1:2])[0]
    ups = [camera[:3, :3].T @ [0.0, 0.0, 1.0] for camera in cameras]
    views = [ViewInput(rgb=f.rgb, depth=f.depth, intrinsics=K, gravity_up=up, camera_pose=camera)
             for f, up, camera in zip(frames, ups, cameras)]
    moved_view = dataclasses.replace(views[1], rgb=moved.rgb, depth=moved.depth)
    return views, [f.target_mask for f in frames], cameras, moved_view, moved.target_mask


def truth(cameras: np.ndarray) -> np.ndarray:
    return np.linalg.inv(cameras[0]) @ cameras


def no_diffusion(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Identity poses and no runner-ups: a diffusion estimate that knows nothing."""
    return np.tile(np.eye(4), (n, 1, 1)), np.full((n, 4, 4), math.nan)


def evidence(view: ViewInput, mask: np.ndarray, extent: float):
    points, valid = backproject(view.depth, view.intrinsics)
    return view_evidence(points, valid, view.intrinsics, view.rgb, mask, object_centre(view, mask), extent)


def yaw_turned(pose: np.ndarray, degrees: float, about: np.ndarray) -> np.ndarray:
    """``pose`` (4, 4) turned by ``degrees`` about the vertical through ``about`` (3,), all in the anchor's frame."""
    turn = np.eye(4)
    turn[:3, :3] = Rotation.from_rotvec(math.radians(degrees) * about[1]).as_matrix()
    turn[:3, 3] = about[0] - turn[:3, :3] @ about[0]
    return turn @ pose


def test_the_verifier_scores_the_true_pose_above_a_turned_one(scene):
    views, masks, cameras, _, _ = scene
    extent = view_cloud(views[0], masks[0]).extent()
    anchor, other = evidence(views[0], masks[0], extent), evidence(views[1], masks[1], extent)
    true_pose = truth(cameras)[1]
    up = views[0].gravity_up
    turned = yaw_turned(true_pose, 40.0, (object_centre(views[0], masks[0]), up))
    right, wrong = verify(anchor, other, true_pose, 0.005), verify(anchor, other, turned, 0.005)
    assert right.score > wrong.score
    assert right.object.support > 0.5 and right.context.free_space < 0.05


def test_a_point_a_pixel_off_an_outline_is_not_in_free_space_but_one_well_clear_of_it_is():
    """A square 0.5 m away before a wall at 1 m: a point at the square's depth that projects one pixel beyond its
    outline (an arm's error, a rounding) is beside the surface, not in front of the wall; one 15 px beyond is."""
    depth = np.full((SIZE, SIZE), 1.0)
    depth[60:100, 60:100] = 0.5
    depth[:5, :5] = 0.0  # no readings in a corner: no nearest reading either
    mask = depth == 0.5
    points, valid = backproject(depth, K)
    rgb = np.full((SIZE, SIZE, 3), 128, np.uint8)
    seen = view_evidence(points, valid, K, rgb, mask, np.array([0.0, 0.0, 0.5]), 0.1)
    assert seen.nearest[2, 2] == 0.0 and seen.nearest[5, 5] == 1.0 and seen.nearest[80, 101] == 0.5

    def free_share(u: float) -> float:
        point = 0.5 * np.linalg.solve(K, [u, 80.0, 1.0])
        return one_way(point[None], np.zeros((1, 2)), seen, seen.object.mask, np.eye(4), 0.001).free_space

    assert free_share(100.0) == 0.0
    assert free_share(115.0) == 1.0
    np.testing.assert_array_equal(nearest_reading(depth, 0), depth)


def test_the_gravity_search_holds_a_yaw_within_its_step_of_the_truth(scene):
    views, masks, cameras, _, _ = scene
    first, second = (view_cloud(views[k], masks[k]) for k in (0, 1))
    hypotheses = gravity_hypotheses(second.points, first.points, views[1].gravity_up, views[0].gravity_up,
                                    object_centre(views[1], masks[1]), object_centre(views[0], masks[0]),
                                    first.extent())
    errors = [float(rotation_angle_deg(h.transform[:3, :3], truth(cameras)[1][:3, :3])) for h in hypotheses]
    assert {h.source for h in hypotheses} == {Source.GRAVITY}
    assert min(errors) <= 2.5 + 0.5  # half the 5-deg yaw step, and the level frames' rounding


def test_the_arm_hypotheses_are_the_cameras_relative_pose_as_measured_and_to_register(scene):
    _, _, cameras, _, _ = scene
    measured = arm_pose(cameras[2], cameras[0])
    np.testing.assert_allclose(measured, truth(cameras)[2], atol=1e-9)
    as_measured, to_register = arm_hypotheses(measured)
    assert {as_measured.source, to_register.source} == {Source.ARM}
    assert as_measured.stages == () and to_register.stages


@pytest.mark.slow
def test_from_a_wrong_diffusion_seed_the_verifier_finds_every_view(scene):
    views, masks, cameras, _, _ = scene
    no_arm = [dataclasses.replace(view, camera_pose=None) for view in views]
    centre = (object_centre(views[0], masks[0]), views[0].gravity_up)
    wrong = np.stack([yaw_turned(pose, 150.0, centre) for pose in truth(cameras)])
    result = verify_with_depth(no_arm, masks, wrong, np.full((3, 4, 4), math.nan), 0.005)
    for k in (1, 2):
        assert rotation_angle_deg(result.poses[k][:3, :3], truth(cameras)[k][:3, :3]) < 3.0
        report = result.views[k]
        assert report.refined and report.source in {"registration", "gravity"} and not report.ambiguous
        assert report.margin > 0 and not report.object_moved
        runner = result.runner_up_poses[k]
        assert np.isnan(runner).all() or not same_pose(runner, result.poses[k], 10.0, 0.02)
    assert result.views[0].note == "the anchor"


@pytest.mark.slow
def test_the_arms_pose_wins_and_a_moved_object_is_flagged(scene):
    views, masks, cameras, moved_view, moved_mask = scene
    kept = verify_with_depth(views[:2], masks[:2], *no_diffusion(2), 0.005)
    assert rotation_angle_deg(kept.poses[1][:3, :3], truth(cameras)[1][:3, :3]) < 1.0
    assert not kept.views[1].object_moved
    moved = verify_with_depth([views[0], moved_view], [masks[0], moved_mask], *no_diffusion(2), 0.005)
    assert moved.views[1].object_moved
    turn = Rotation.from_euler("z", -MOVED_DEG, degrees=True).as_matrix()
    relative_to_object = cameras[0][:3, :3].T @ turn @ cameras[1][:3, :3]
    assert rotation_angle_deg(moved.poses[1][:3, :3], relative_to_object) < 10.0, "the pose is the object's"


@pytest.mark.slow
def test_without_gravity_a_view_needs_the_larger_lead_to_be_unambiguous(scene):
    views, masks, _, _, _ = scene
    registration = frozenset({Source.REGISTRATION})
    strict = VerificationSettings(sources=registration, ambiguity_margin=0.0, ambiguity_margin_without_gravity=1e6)
    no_gravity = [dataclasses.replace(view, gravity_up=None, camera_pose=None) for view in views[:2]]
    without = verify_with_depth(no_gravity, masks[:2], *no_diffusion(2), 0.005, strict).views[1]
    assert without.ambiguous is True and "without gravity the best must lead by 1e+06" in without.note
    with_gravity = [dataclasses.replace(view, camera_pose=None) for view in views[:2]]
    assert not verify_with_depth(with_gravity, masks[:2], *no_diffusion(2), 0.005, strict).views[1].ambiguous


def test_a_pose_near_the_arms_gets_its_prior_whatever_its_source_and_the_diffusion_answer_its_trust():
    def turned(degrees: float) -> np.ndarray:
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_euler("z", degrees, degrees=True).as_matrix()
        return pose

    near, far = turned(ARM_TOLERANCE_DEG / 2), turned(2 * DIFFUSION_TOLERANCE_DEG)
    assert Priors(arm=np.eye(4)).of(near, 0.2) == ARM_PRIOR > 0.0
    assert Priors(arm=np.eye(4)).of(far, 0.2) == 0.0 == Priors().of(near, 0.2)
    trusted = Priors(diffusion=np.eye(4), diffusion_weight=0.4)
    assert trusted.of(near, 0.2) == 0.4 and trusted.of(far, 0.2) == 0.0
    assert Priors(np.eye(4), np.eye(4), 0.4).of(near, 0.2) == ARM_PRIOR + 0.4


def test_only_the_diffusion_source_is_asked_when_the_others_are_off(scene):
    views, masks, _, _, _ = scene
    poses, runners = no_diffusion(2)
    result = verify_with_depth(views[:2], masks[:2], poses, runners, 0.005, VerificationSettings(sources=frozenset()))
    assert result.views[1].source == "diffusion"


@pytest.mark.parametrize("broken, note", [
    (lambda view: dataclasses.replace(view, depth=None), "no depth: the diffusion pose"),
    (lambda view: dataclasses.replace(view, depth=np.zeros_like(view.depth)), "no depth on the object"),
    (lambda view: dataclasses.replace(view, depth=np.full_like(view.depth, np.nan)), "no depth on the object"),
    (lambda view: dataclasses.replace(view, depth=view.depth[:-8]), "does not match the image"),
])
def test_a_view_without_usable_depth_keeps_its_diffusion_pose_and_says_why(scene, broken, note):
    views, masks, _, _, _ = scene
    diffusion = np.tile(np.eye(4), (3, 1, 1))
    diffusion[2, :3, 3] = [0.1, 0.0, 0.0]
    result = verify_with_depth([views[0], views[1], broken(views[2])], masks, diffusion, np.full((3, 4, 4), math.nan),
                               0.005, VerificationSettings(sources=frozenset()))  # the diffusion source only: quick
    assert note in result.views[2].note and not result.views[2].refined
    np.testing.assert_allclose(result.poses[2], diffusion[2])
    assert result.views[1].refined


def test_an_anchor_without_depth_leaves_the_poses_to_the_diffusion_estimate(scene):
    views, masks, _, _, _ = scene
    assert verify_with_depth([dataclasses.replace(views[0], depth=None), views[1]], masks[:2],
                             *no_diffusion(2), 0.005) is None


@pytest.mark.slow
def test_a_view_whose_mask_is_unsure_stays_out_of_the_fused_cloud_but_keeps_its_pose(scene):
    views, masks, _, _, _ = scene
    settings = VerificationSettings(sources=frozenset({Source.REGISTRATION, Source.GRAVITY}))
    both = verify_with_depth(views[:2], masks[:2], *no_diffusion(2), 0.005, settings)
    alone = verify_with_depth(views[:2], masks[:2], *no_diffusion(2), 0.005, settings, fuse=[True, False])
    assert both.views[1].refined and not both.views[1].ambiguous, "the view is placed: it would be fused"
    np.testing.assert_array_equal(alone.poses, both.poses)
    anchor_only = verify_with_depth(views[:1] * 2, masks[:1] * 2, *no_diffusion(2), 0.005, settings,
                                    fuse=[True, False]).cloud
    assert len(alone.cloud.points) == len(anchor_only.points) < len(both.cloud.points)
