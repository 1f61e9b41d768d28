"""The evaluation protocol of idpose_core.evaluation: picks, stamp matching, object frame, scoring."""
import math

import numpy as np
import pytest

from idpose_core.cameras import anchor_frame_poses, opengl_to_optical, spherical_to_c2w
from idpose_core.evaluation.object_frame import object_frame_c2w, world_cameras, world_to_object
from idpose_core.evaluation.picks import distinct_pair_count, draw_picks
from idpose_core.evaluation.scoring import score_poses
from idpose_core.gravity import with_roll
from idpose_core.stamps import match_stamps
from idpose_core.synthetic.scenes import rolled_optical_frames
from idpose_core.transforms import invert_transform


def test_picks_are_seeded_and_open_with_different_pairs_in_capture_order():
    pool = [0, 2, 3, 5, 7, 8, 9, 11, 12, 14, 15]
    picks = draw_picks(pool, samples=20, seed=3)
    assert picks == draw_picks(pool, samples=20, seed=3)
    assert picks != draw_picks(pool, samples=20, seed=4)
    for pick in picks:
        assert len(pick) == 8 and len(set(pick)) == 8 and set(pick) <= set(pool)
        assert pick[0] < pick[1] and pick[2:] == sorted(pick[2:])
    assert len({tuple(pick[:2]) for pick in picks}) == 20


def test_a_small_pool_gives_one_pick_per_pair_never_a_repeat():
    picks = draw_picks([4, 1, 9], samples=5, seed=0)
    assert len(picks) == distinct_pair_count(3) == 3
    assert sorted(tuple(pick[:2]) for pick in picks) == [(1, 4), (1, 9), (4, 9)]
    assert all(sorted(pick) == [1, 4, 9] for pick in picks)
    assert [pick[:2] for pick in draw_picks([1, 2, 3, 4, 5, 6], samples=15, seed=1)] != [[1, 2]] * 15


def test_tiny_pools_and_no_samples_are_refused():
    with pytest.raises(ValueError, match="at least 2 usable views"):
        draw_picks([4], samples=1, seed=0)
    with pytest.raises(ValueError, match="samples"):
        draw_picks([1, 2], samples=0, seed=0)


def test_match_stamps_nearest_within_tolerance():
    stamps = [300, 100, 200]
    np.testing.assert_array_equal(match_stamps([100, 205, 260, 400, 0], stamps, tolerance=10), [1, 2, -1, -1, -1])
    np.testing.assert_array_equal(match_stamps([250], stamps, tolerance=50), [2])  # a tie takes the earlier
    np.testing.assert_array_equal(match_stamps([5], [], tolerance=10), [-1])


@pytest.mark.parametrize("up", [(0, 0, 1), (0, 1, 0), (0, 0, -1), (1, -2, 0.5)])
def test_world_to_object_sends_up_to_z_and_center_to_origin(up):
    center = np.array([0.3, -1.0, 2.0])
    transform = world_to_object(center, up)
    np.testing.assert_allclose(transform[:3, :3] @ (np.array(up) / np.linalg.norm(up)), [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(transform[:3, :3] @ transform[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.linalg.det(transform[:3, :3]) == pytest.approx(1.0)
    np.testing.assert_allclose((transform @ np.append(center, 1.0))[:3], 0.0, atol=1e-12)
    with pytest.raises(ValueError, match="non-zero"):
        world_to_object(center, (0, 0, 0))


def test_true_cameras_in_a_tilted_world_score_perfectly_with_their_own_poses():
    """Cameras placed around an object at (0.3, -1, 2) with world up +y come back as the spherical poses they had."""
    sph = np.array([[1.2, 0.4, 2.0], [0.7, 2.0, 2.5], [2.3, 5.5, 1.8]])
    c2w = spherical_to_c2w(sph)
    center, up = (0.3, -1.0, 2.0), (0.0, 1.0, 0.0)
    world_from_optical = invert_transform(world_to_object(center, up)) @ opengl_to_optical(c2w)
    recovered = object_frame_c2w(world_from_optical, center, up)
    np.testing.assert_allclose(recovered, c2w, atol=1e-12)

    true_rel = np.array([[0.7 - 1.2, 2.0 - 0.4, 0.5 * 1.85 / 2.0], [2.3 - 1.2, 5.5 - 0.4, -0.2 * 1.85 / 2.0]])
    poses = anchor_frame_poses(true_rel, anchor_polar=1.2, object_distance=2.0)  # as the node publishes them
    records = score_poses(poses, recovered)
    for record, expected in zip(records, true_rel):
        np.testing.assert_allclose(record["true_rel_sph"], expected, atol=1e-12)
        np.testing.assert_allclose(record["pred_rel_sph"], expected, atol=1e-9)
        assert record["rot_err_deg"] == pytest.approx(0.0, abs=1e-5)
        assert record["pos_err"] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(world_cameras(poses, c2w[0]), c2w, atol=1e-9)


def test_a_wrong_azimuth_costs_its_angle():
    sph = np.array([[math.pi / 2, 0.0, 2.0], [math.pi / 2, 1.0, 2.0]])
    poses = anchor_frame_poses(np.array([[0.0, 1.0 + math.radians(20), 0.0]]), math.pi / 2, 2.0)
    (record,) = score_poses(poses, spherical_to_c2w(sph))
    assert record["rot_err_deg"] == pytest.approx(20.0, abs=1e-6)
    assert record["pos_err"] == pytest.approx(2 * math.sin(math.radians(10)), abs=1e-9)  # chord / radius
    with pytest.raises(ValueError, match="3 estimated poses for 2 cameras"):
        score_poses(np.stack([np.eye(4)] * 3), spherical_to_c2w(sph))


def test_rolled_cameras_score_by_their_real_frames():
    """Poses with each view's roll put back score zero; the upright poses are off by the roll difference."""
    sph = np.array([[1.1, 0.3, 2.0], [0.8, 1.9, 2.0]])
    rolls = np.radians([20.0, -35.0])
    true_c2w = opengl_to_optical(rolled_optical_frames(sph, rolls))
    upright = anchor_frame_poses(sph[1:] - sph[:1], anchor_polar=1.1, object_distance=2.0)
    (exact,) = score_poses(with_roll(upright, rolls), true_c2w)
    assert exact["rot_err_deg"] == pytest.approx(0.0, abs=1e-5) and exact["pos_err"] == pytest.approx(0.0, abs=1e-9)
    (unrolled,) = score_poses(upright, true_c2w)
    assert unrolled["rot_err_deg"] > 30.0 and unrolled["pos_err"] > 0.3
