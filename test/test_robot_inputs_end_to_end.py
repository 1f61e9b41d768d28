"""Gravity and depth end to end through evaluate_bag: rolled cameras come back with their roll, tabletop views
are cut out by depth and scaled by it, and the node (replay) reads the same inputs as the offline pipeline.

The predictor is the IdentifyingOracle (the ideal denoiser of the rendered scene, told which camera each
view came from by its upright thumbnail): a rolled view is only recognised once it has been turned
upright, so a perfect score needs gravity to work. Reduced for speed: 96 px views, one pick, n = 2 and
3, the fast preset with 30 refinement steps.
"""
import math
from dataclasses import replace

import numpy as np
import pytest

from idpose_core.evaluation.picks import draw_picks
from idpose_core.evaluation.protocol import EvaluationProtocol
from idpose_core.synthetic.render_oracle import IdentifyingOracle, RenderOracle
from idpose_core.synthetic.scenes import demo_objects, random_camera_spheres
from idpose_core.synthetic.tabletop import tabletop_cameras
from idpose_ros.dataset.synthetic_bag import (
    ARM_TOPIC,
    DEPTH_TOPIC,
    IMU_TOPIC,
    ORIENTATION_TOPIC,
    SyntheticBagOptions,
    make_bag,
)
from idpose_ros.evaluation import estimators
from idpose_ros.evaluation.bag_evaluation import evaluate_bag
from idpose_ros.evaluation.bag_views import ExtraTopics
from idpose_ros.evaluation.estimators import EstimatorOptions, OfflineEstimator
from idpose_ros.evaluation.ground_truth import GroundTruthOptions

SEED, VIEWS, SIZE, ROLL_DEG = 11, 6, 96, 40.0
ORACLE = EstimatorOptions(preset="fast", image_size=96,
                          solver_params=("adjust_lr=1.0", "refine_lr=0.1", "refine_steps_per_view=30"))
PROTOCOL = EvaluationProtocol(samples=1, seed=SEED, view_counts=(2, 3))


def oracle_for(seed: int, size: int) -> IdentifyingOracle:
    cameras = random_camera_spheres(np.random.default_rng(seed), VIEWS)  # the bag's cameras, from its seed
    return IdentifyingOracle(demo_objects()[0], cameras, size)


@pytest.fixture(scope="module")
def rolled_bag(tmp_path_factory):
    path = tmp_path_factory.mktemp("rolled") / "bag"
    make_bag(path, SyntheticBagOptions("mcap", "demo", None, views=VIEWS, seed=SEED, size=SIZE, roll_deg=ROLL_DEG))
    return path


@pytest.mark.parametrize("topic", [IMU_TOPIC, ORIENTATION_TOPIC])
def test_rolled_cameras_come_back_with_their_roll(rolled_bag, topic):
    """The Imu (mounted with camera_link's axes: the extrinsic comes from /tf_static) and the orientation topic."""
    oracle = oracle_for(SEED, SIZE)
    estimator = OfflineEstimator(oracle, ORACLE.node_values())
    run = evaluate_bag(rolled_bag, estimator, GroundTruthOptions(extras=ExtraTopics(gravity_topic=topic)), PROTOCOL,
                       show_progress=False)
    assert len(run.records) == 1 + 2
    assert all(record["rot_err_deg"] < 5.0 for record in run.records), [r["rot_err_deg"] for r in run.records]
    rolls = [view["roll_deg"] for estimate in run.estimates for view in estimate["details"]["views"]]
    assert max(abs(roll) for roll in rolls) > 10.0 and all(abs(roll) <= ROLL_DEG + 1e-6 for roll in rolls)
    assert {estimate["details"]["polar_source"] for estimate in run.estimates} == {"gravity"}
    for estimate in run.estimates:  # gravity's polar angle of the anchor, along the ray to the mask's middle
        assert estimate["details"]["anchor_polar_deg"] == pytest.approx(estimate["anchor_polar_deg"], abs=5.0)


def test_without_gravity_a_rolled_view_is_not_even_recognised(rolled_bag):
    estimator = OfflineEstimator(oracle_for(SEED, SIZE), ORACLE.node_values())
    with pytest.raises(ValueError, match="ambiguous view identification"):
        evaluate_bag(rolled_bag, estimator, GroundTruthOptions(), PROTOCOL, show_progress=False)


def test_a_tabletop_bag_is_cut_out_and_scaled_by_depth(tmp_path):
    """Every view's mask comes from depth, the anchor's distance too; the predictor (the render oracle of the
    pick's cameras) only has to run: accuracy on tabletop scenes is measured by bench/tabletop.py."""
    bag = make_bag(tmp_path / "tabletop", SyntheticBagOptions(views=4, seed=SEED, scene="tabletop"))
    pick = draw_picks(list(range(4)), 1, SEED)[0][:2]  # n = 2: its first two views
    cameras = tabletop_cameras(np.random.default_rng(SEED), 4)[pick]
    oracle = RenderOracle(demo_objects()[0], np.column_stack([cameras[:, :2], np.full(len(pick), 2.0)]),
                          step_deg=15.0)
    estimator = OfflineEstimator(oracle, ORACLE.node_values())
    options = GroundTruthOptions(extras=ExtraTopics(depth_topic=DEPTH_TOPIC, gravity_topic=IMU_TOPIC))
    run = evaluate_bag(bag, estimator, options, EvaluationProtocol(1, SEED, (2,)), show_progress=False)
    (estimate,) = run.estimates
    details = estimate["details"]
    assert [view["mask_method"] for view in details["views"]] == ["depth", "depth"]
    assert (details["distance_source"], details["polar_source"]) == ("depth", "gravity")
    assert details["object_distance"] == pytest.approx(estimate["object_distance"], rel=0.08)  # the true distance
    without = evaluate_bag(bag, estimator, GroundTruthOptions(), EvaluationProtocol(1, SEED, (2,)),
                           show_progress=False)
    assert without.estimates[0]["details"]["distance_source"] == "parameter"
    assert {view["mask_method"] for view in without.estimates[0]["details"]["views"]} <= {"threshold", "grabcut"}


@pytest.mark.slow
def test_replay_reads_the_same_gravity_as_offline(rolled_bag):
    """The node gets each view's gravity on its camera_orientation topic from the replay client."""
    oracle = oracle_for(SEED, SIZE)
    options = GroundTruthOptions(extras=ExtraTopics(gravity_topic=IMU_TOPIC))
    protocol = EvaluationProtocol(1, SEED, (3,))
    runs = {}
    for mode in ("offline", "replay"):
        estimator = estimators.make_estimator(replace(ORACLE, mode=mode), predictor=oracle)
        try:
            runs[mode] = evaluate_bag(rolled_bag, estimator, options, protocol, show_progress=False)
        finally:
            estimator.close()
    for offline, replay in zip(runs["offline"].records, runs["replay"].records):
        np.testing.assert_allclose(offline["pred_rel_sph"], replay["pred_rel_sph"], atol=1e-6)
        assert offline["rot_err_deg"] == pytest.approx(replay["rot_err_deg"], abs=1e-4)
    assert all(record["rot_err_deg"] < 5.0 for record in runs["replay"].records)
    assert math.isfinite(runs["replay"].estimates[0]["seconds"])
    for offline, replay in zip(runs["offline"].estimates, runs["replay"].estimates):
        assert replay["details"]["polar_source"] == "gravity"
        assert_same_details(offline["details"], replay["details"])


def assert_same_details(offline, replay) -> None:
    """Equal, numbers to float32 precision (the action result carries angles and distances as float32)."""
    if isinstance(offline, dict):
        assert offline.keys() == replay.keys()
        for key in offline:
            assert_same_details(offline[key], replay[key])
    elif isinstance(offline, list):
        assert len(offline) == len(replay)
        for a, b in zip(offline, replay):
            assert_same_details(a, b)
    elif isinstance(offline, float):
        assert replay == pytest.approx(offline, rel=1e-6, abs=1e-5, nan_ok=True)
    else:
        assert offline == replay


@pytest.mark.slow
def test_the_arms_camera_poses_in_a_bag_pose_the_views_with_depth(tmp_path):
    """The bag's /arm/camera_pose (the optical frame in the world, off by an arm's error) gives gravity and the
    arm's pose hypotheses: every non-anchor view's pose is the verifier's, within a few degrees of the truth,
    whatever the predictor (a render oracle of another camera set, so its own poses are wrong)."""
    bag = make_bag(tmp_path / "tabletop", SyntheticBagOptions(views=4, seed=SEED, scene="tabletop"))
    wrong = RenderOracle(demo_objects()[0], np.array([[1.2, 0.3, 2.0], [1.0, 2.5, 2.0]]), step_deg=15.0)
    estimator = OfflineEstimator(wrong, ORACLE.node_values())
    options = GroundTruthOptions(extras=ExtraTopics(depth_topic=DEPTH_TOPIC, gravity_topic=ARM_TOPIC))
    run = evaluate_bag(bag, estimator, options, EvaluationProtocol(1, SEED, (2,)), show_progress=False)
    (estimate,) = run.estimates
    other = estimate["details"]["views"][1]["refinement"]
    assert other["refined"] and other["source"] in {"arm", "gravity", "registration", "diffusion"}
    assert math.isfinite(other["margin"]) and not other["object_moved"]
    assert all(record["rot_err_deg"] < 3.0 for record in run.records), [r["rot_err_deg"] for r in run.records]
