"""The classical baselines on rendered views with known poses: COLMAP and the two-view SIFT baseline recover
them within a few degrees, COLMAP retries with fewer views, failures are scored as random guesses."""
import math

import cv2
import numpy as np
import pytest

from idpose_core.baselines import BASELINES, CONVERGED, DEFAULT_FOV_DEG, FAILED, FEWER, run_baseline
from idpose_core.baselines.colmap import estimate_colmap
from idpose_core.baselines.features import estimate_features
from idpose_core.baselines.result import BaselineEstimate, object_centre, scale_to_object_distance
from idpose_core.baselines.scoring import estimate_summary, score_baseline
from idpose_core.cameras import opengl_to_optical, pinhole_camera_matrix, spherical_to_c2w
from idpose_core.metrics import rotation_angle_deg
from idpose_core.synthetic.scenes import CAMERA_RADIUS, SceneRenderer, textured_objects

SIZE = 512
CAMERA_MATRIX = pinhole_camera_matrix(SIZE, SIZE, 60.0)


def cameras(*polar_azimuth_deg: tuple[float, float]) -> np.ndarray:
    return np.array([[math.radians(p), math.radians(a), CAMERA_RADIUS] for p, a in polar_azimuth_deg])


def render(name: str, spheres: np.ndarray) -> list[np.ndarray]:
    spec = next(s for s in textured_objects() if s.name == name)
    with SceneRenderer(spec, image_size=SIZE) as renderer:
        return [renderer.render(*sph)[0] for sph in spheres]


def true_poses(spheres: np.ndarray) -> np.ndarray:
    """Optical camera poses (n, 4, 4) in the first camera's frame, metres."""
    world_from_camera = opengl_to_optical(spherical_to_c2w(spheres))
    return np.linalg.inv(world_from_camera[0]) @ world_from_camera


def pose_errors(estimate: BaselineEstimate, spheres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rotation errors in degrees, camera-centre errors / distance) of views 1..n-1."""
    truth = true_poses(spheres)
    rotation = rotation_angle_deg(estimate.poses[1:, :3, :3], truth[1:, :3, :3])
    return rotation, np.linalg.norm(estimate.poses[1:, :3, 3] - truth[1:, :3, 3], axis=-1) / CAMERA_RADIUS


def test_the_feature_baseline_recovers_a_known_relative_pose():
    spheres = cameras((70, 20), (75, 30))
    estimate = estimate_features(render("motor_crate", spheres), CAMERA_MATRIX, CAMERA_RADIUS)
    assert estimate.status == CONVERGED and estimate.registered.all()
    rotation, position = pose_errors(estimate, spheres)
    assert rotation[0] < 3.0 and position[0] < 0.1
    # scored as ID-Pose is: the paper's errors of the relative spherical pose
    record = score_baseline(estimate, spherical_to_c2w(spheres), spheres[0, 0], CAMERA_RADIUS,
                            np.random.default_rng(0))[0]
    assert record["registered"] and record["rot_err_deg"] < 3.0 and record["pos_err"] < 0.1


def test_colmap_recovers_known_poses_quietly(capfd):
    spheres = cameras((70, 20), (75, 30), (65, 40))
    estimate = estimate_colmap(render("numbered_cube", spheres), CAMERA_MATRIX, CAMERA_RADIUS)
    assert estimate.status == CONVERGED and estimate.registered.all()
    rotation, position = pose_errors(estimate, spheres)
    assert rotation.max() < 3.0 and position.max() < 0.1
    assert capfd.readouterr().err == ""  # no COLMAP log on the terminal


def test_colmap_retries_with_fewer_views_and_fails_without_texture():
    spheres = cameras((70, 20), (75, 30), (65, 40), (110, 200))  # the last one sees the cube's other side
    estimate = estimate_colmap(render("numbered_cube", spheres), CAMERA_MATRIX, CAMERA_RADIUS)
    assert estimate.status == FEWER and estimate.registered.tolist() == [True, True, True, False]
    assert pose_errors(estimate, spheres)[0][:2].max() < 3.0
    blank = [np.full((SIZE, SIZE, 3), 255, np.uint8)] * 3
    for baseline in (estimate_colmap, estimate_features):
        failed = baseline(blank, CAMERA_MATRIX, CAMERA_RADIUS)
        assert failed.status == FAILED and failed.registered.tolist() == [True, False, False]


def test_the_object_centre_fixes_the_scale():
    spheres = cameras((60, 0), (80, 50), (100, 120))
    poses = true_poses(spheres)
    np.testing.assert_allclose(object_centre(poses), [0.0, 0.0, CAMERA_RADIUS], atol=1e-9)
    shrunk = poses.copy()
    shrunk[:, :3, 3] *= 0.3  # what structure from motion gives: the right shape at an unknown scale
    scaled = scale_to_object_distance(shrunk, np.array([True, True, False]), CAMERA_RADIUS)
    np.testing.assert_allclose(scaled, poses, atol=1e-9)
    parallel = np.repeat(np.eye(4)[None], 2, axis=0)
    parallel[1, 0, 3] = 0.5  # a sideways step without turning: the axes never meet
    assert object_centre(parallel) is None and scale_to_object_distance(parallel, np.ones(2, bool), 2.0) is None


def test_unplaced_views_are_scored_as_seeded_random_guesses():
    spheres = cameras((60, 0), (80, 50), (100, 120))
    truth_c2w = spherical_to_c2w(spheres)
    estimate = BaselineEstimate(true_poses(spheres), np.array([True, True, False]), FEWER, 0.1)
    records = score_baseline(estimate, truth_c2w, spheres[0, 0], CAMERA_RADIUS, np.random.default_rng(3))
    assert [r["registered"] for r in records] == [True, False]
    assert records[0]["rot_err_deg"] < 1e-6 and records[0]["pos_err"] < 1e-9
    again = score_baseline(estimate, truth_c2w, spheres[0, 0], CAMERA_RADIUS, np.random.default_rng(3))
    assert again[1]["rot_err_deg"] == records[1]["rot_err_deg"] > 1.0
    guesses = [score_baseline(estimate, truth_c2w, spheres[0, 0], CAMERA_RADIUS, np.random.default_rng(seed))[1]
               for seed in range(300)]
    assert 70.0 < np.mean([g["rot_err_deg"] for g in guesses]) < 130.0  # as the random-pose row


def test_estimate_summary_gives_the_papers_counts():
    rows = [{"n": 2, "status": CONVERGED, "seconds": 1.0}, {"n": 2, "status": FAILED, "seconds": 3.0},
            {"n": 4, "status": FEWER, "seconds": 2.0}]
    summary = estimate_summary(rows)
    assert list(summary) == ["2", "4", "all"]
    assert summary["2"] == {"estimates": 2, "mean_seconds": 2.0, "converged": 1, "fewer": 0}
    assert summary["all"] == {"estimates": 3, "mean_seconds": 2.0, "converged": 1, "fewer": 1}
    assert estimate_summary([{"n": 2, "seconds": 5.0}])["all"] == {"estimates": 1, "mean_seconds": 5.0}


def test_run_baseline_whitens_the_background_and_defaults_the_intrinsics(monkeypatch):
    seen = {}

    def spy(images, camera_matrix, distance):
        seen.update(images=images, camera_matrix=camera_matrix, distance=distance)
        return BaselineEstimate.failure(len(images), 0.0)

    monkeypatch.setitem(BASELINES, "spy", spy)
    rgb = np.zeros((4, 6, 3), np.uint8)
    alpha = np.zeros((4, 6), np.uint8)
    alpha[1:3, 2:4] = 255
    run_baseline("spy", [(rgb, alpha), (rgb, None)], None, 1.5)
    assert seen["images"][0][0, 0].tolist() == [255, 255, 255] and seen["images"][0][1, 2].tolist() == [0, 0, 0]
    assert not seen["images"][1].any() and seen["distance"] == 1.5
    np.testing.assert_allclose(seen["camera_matrix"], pinhole_camera_matrix(6, 4, DEFAULT_FOV_DEG))
    with pytest.raises(ValueError, match="unknown baseline 'relpose'"):
        run_baseline("relpose", [(rgb, None)] * 2, None, 1.0)


def test_the_textured_objects_are_asymmetric_and_detailed():
    specs = textured_objects()
    assert len({s.name for s in specs}) == len(specs) >= 4 and not any(s.symmetric for s in specs)
    for spec in specs:
        with SceneRenderer(spec, image_size=256) as renderer:
            rgb, mask = renderer.render(math.radians(70), 0.5)
        keypoints = cv2.SIFT_create().detect(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY))
        assert mask.mean() > 0.05 and len(keypoints) >= 50, (spec.name, len(keypoints))
