"""The pose graph: views placed off their measurements come back to them, the loop residual is near zero where
the measurements agree and large at a view whose measurements contradict each other."""
import numpy as np
from scipy.spatial.transform import Rotation

from idpose_core.metrics import rotation_angle_deg
from idpose_core.pose_hypotheses.pose_graph import Edge, optimise


def pose(rotvec_deg, translation) -> np.ndarray:
    transform = np.eye(4)
    transform[:3, :3] = Rotation.from_rotvec(np.radians(rotvec_deg)).as_matrix()
    transform[:3, 3] = translation
    return transform


TRUTH = {0: np.eye(4), 1: pose([0, 40, 0], [0.3, 0.0, 0.05]), 2: pose([0, 80, 5], [0.55, 0.0, 0.3])}


def edges_of(poses, pairs):
    return [Edge(a, b, np.linalg.inv(poses[a]) @ poses[b]) for a, b in pairs]


def test_views_placed_off_their_measurements_come_back():
    edges = edges_of(TRUTH, [(0, 1), (1, 2), (0, 2)])
    start = {0: np.eye(4), 1: TRUTH[1] @ pose([3, -2, 1], [0.01, 0, 0]), 2: TRUTH[2] @ pose([-4, 3, 2], [0, 0.02, 0])}
    fitted, loops = optimise(start, edges, extent=0.2)
    for k in (1, 2):
        assert rotation_angle_deg(fitted[k][:3, :3], TRUTH[k][:3, :3]) < 0.1
        np.testing.assert_allclose(fitted[k][:3, 3], TRUTH[k][:3, 3], atol=1e-3)
        assert loops[k] < 0.1


def test_contradicting_measurements_leave_a_loop_residual():
    wrong = dict(TRUTH)
    wrong[2] = TRUTH[2] @ pose([0, 30, 0], [0, 0, 0])  # the pair (1, 2) measures view 2 turned 30 deg
    edges = edges_of(TRUTH, [(0, 1), (0, 2)]) + edges_of(wrong, [(1, 2)])
    _, loops = optimise(dict(TRUTH), edges, extent=0.2)
    assert loops[2] > 5.0


def test_without_edges_the_placement_stays():
    fitted, loops = optimise(TRUTH, [], extent=0.2)
    assert all(np.array_equal(fitted[k], TRUTH[k]) for k in TRUTH) and loops == {1: 0.0, 2: 0.0}
