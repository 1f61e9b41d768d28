"""The evaluation protocol of idpose_core.evaluation: picks, stamp matching, object frame, scoring."""
import math

import numpy as np
import pytest

from idpose_core.cameras import anchor_frame_poses, opengl_to_optical, spherical_to_c2w
from idpose_core.evaluation import (
    draw_picks,
    match_stamps,
    object_frame_c2w,
    predicted_c2w,
    relative_from_anchor_frame,
    score_pairs,
    world_to_object,
)
from idpose_core.transforms import invert_transform


def test_picks_are_seeded_distinct_sorted_subsets():
    pool = [0, 2, 3, 5, 7, 8, 9, 11, 12, 14, 15]
    picks = draw_picks(pool, samples=5, seed=3)
    assert picks == draw_picks(pool, samples=5, seed=3)
    assert picks != draw_picks(pool, samples=5, seed=4)
    for pick in picks:
        assert len(pick) == 8 and len(set(pick)) == 8
        assert pick == sorted(pick) and set(pick) <= set(pool)
    assert len({tuple(p) for p in picks}) > 1


def test_small_pools_give_smaller_picks_and_tiny_ones_are_refused():
    assert draw_picks([4, 1, 9], samples=2, seed=0) == [[1, 4, 9], [1, 4, 9]]
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
    records = score_pairs(true_rel, recovered)
    for record, expected in zip(records, true_rel):
        np.testing.assert_allclose(record["true_rel_sph"], expected, atol=1e-12)
        assert record["rot_err_deg"] == pytest.approx(0.0, abs=1e-5)
        assert record["pos_err"] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(predicted_c2w(c2w[0], true_rel), c2w[1:], atol=1e-9)


def test_a_wrong_azimuth_costs_its_angle():
    c2w = spherical_to_c2w(np.array([[math.pi / 2, 0.0, 2.0], [math.pi / 2, 1.0, 2.0]]))
    (record,) = score_pairs(np.array([[0.0, 1.0 + math.radians(20), 0.0]]), c2w)
    assert record["rot_err_deg"] == pytest.approx(20.0, abs=1e-6)
    assert record["pos_err"] == pytest.approx(2 * math.sin(math.radians(10)), abs=1e-9)  # chord / radius
    with pytest.raises(ValueError, match="one fewer"):
        score_pairs(np.zeros((2, 3)), c2w)


def test_relative_from_anchor_frame_inverts_anchor_frame_poses():
    rel = np.array([[0.3, 1.0, 0.1], [-0.5, 4.0, -0.2], [0.0, 2.5, 0.0]])
    poses = anchor_frame_poses(rel, anchor_polar=1.1, object_distance=1.7)
    np.testing.assert_allclose(relative_from_anchor_frame(poses, 1.1, 1.7), rel, atol=1e-9)
