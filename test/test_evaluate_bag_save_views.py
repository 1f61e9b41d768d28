"""evaluate_bag --save-views on a real tabletop bag: masks in the original pixels, crops, IoU against the truth, and
the fused object cloud as a PLY file.

The bag is rolled (cameras turned up to 35 deg about their axes, gravity on the Imu topic), so the pipeline
de-rolls every view and the saved masks must be mapped back to the images' own pixels to match the true
masks. The predictor is the render oracle of the pick's cameras: it only has to run. Reduced for speed:
4 views of 160 px, one pick, n = 3, the fast preset with 30 refinement steps.
"""
import json

import cv2
import numpy as np
import pytest
from plyfile import PlyData

from idpose_core.evaluation.picks import draw_picks
from idpose_core.evaluation.protocol import EvaluationProtocol
from idpose_core.preprocessing import mask_iou
from idpose_core.synthetic.render_oracle import RenderOracle
from idpose_core.synthetic.scenes import demo_objects
from idpose_core.synthetic.tabletop import tabletop_cameras
from idpose_ros import evaluate_bag as evaluate_bag_command
from idpose_ros.dataset.synthetic_bag import DEPTH_TOPIC, IMAGE_TOPIC, IMU_TOPIC, SyntheticBagOptions, make_bag
from idpose_ros.evaluation.bag_evaluation import evaluate_bag
from idpose_ros.evaluation.bag_report import write_report
from idpose_ros.evaluation.bag_views import ExtraTopics, read_bag_views
from idpose_ros.evaluation.estimators import EstimatorOptions, OfflineEstimator
from idpose_ros.evaluation.ground_truth import TRUE_MASK_TOPIC, GroundTruthOptions
from idpose_ros.evaluation.view_masks import read_true_masks

SEED, VIEWS, SIZE = 21, 4, 160
ORACLE = EstimatorOptions(preset="fast", image_size=64,
                          solver_params=("adjust_lr=1.0", "refine_lr=0.1", "refine_steps_per_view=30"))
PROTOCOL = EvaluationProtocol(samples=1, seed=SEED, view_counts=(3,))
INPUTS = GroundTruthOptions(extras=ExtraTopics(depth_topic=DEPTH_TOPIC, gravity_topic=IMU_TOPIC))


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    return make_bag(tmp_path_factory.mktemp("save_views") / "bag",
                    SyntheticBagOptions(views=VIEWS, seed=SEED, size=SIZE, scene="tabletop", roll_deg=35.0))


@pytest.fixture(scope="module")
def saved(bag, tmp_path_factory):
    pick = draw_picks(list(range(VIEWS)), 1, SEED)[0][:3]
    cameras = tabletop_cameras(np.random.default_rng(SEED), VIEWS)[pick]
    oracle = RenderOracle(demo_objects()[0], np.column_stack([cameras[:, :2], np.full(len(pick), 2.0)]),
                          step_deg=15.0)
    out = tmp_path_factory.mktemp("saved")
    run = evaluate_bag(bag, OfflineEstimator(oracle, ORACLE.node_values()), INPUTS, PROTOCOL, show_progress=False,
                       save_views=out / "saved")
    write_report(out / "report", run)
    return run, out


def test_every_used_view_has_its_mask_in_the_original_pixels_and_its_crop(bag, saved):
    run, out = saved
    used = sorted({view for estimate in run.estimates for view in estimate["views"]})
    assert len(run.estimates) == 1 and len(used) == 3
    assert {view["roll_deg"] is not None for e in run.estimates for view in e["details"]["views"]} == {True}
    views = read_bag_views(bag, IMAGE_TOPIC)
    truth = read_true_masks(bag, TRUE_MASK_TOPIC, views, set(used), 0.01)
    assert sorted(truth) == used
    for view_id in used:
        mask = cv2.imread(str(out / "saved" / "views" / f"{view_id}_mask.png"), cv2.IMREAD_UNCHANGED)
        assert mask.dtype == np.uint8 and mask.shape == (SIZE, SIZE)  # the image's frame, not the upright canvas
        assert set(np.unique(mask)) <= {0, 255}
        assert mask_iou(mask > 0, truth[view_id]) > 0.6, view_id  # mapped back onto the target, not rotated off
        crop = cv2.imread(str(out / "saved" / "views" / f"{view_id}_crop.png"), cv2.IMREAD_UNCHANGED)
        assert crop.shape == (64, 64, 3) and (crop == 255).all(axis=-1).mean() > 0.2  # object on white
    assert sorted(p.name for p in (out / "saved" / "views").iterdir()) == sorted(
        f"{v}_{kind}.png" for v in used for kind in ("crop", "mask"))


def test_the_estimate_s_object_cloud_is_saved_as_ply(saved):
    """The cloud of pick 0 at n = 3, in the anchor's optical frame: around the object centre the depth measured."""
    run, out = saved
    (estimate,) = run.estimates
    assert sorted(p.name for p in (out / "saved" / "clouds").iterdir()) == ["0_3.ply"]
    vertices = PlyData.read(str(out / "saved" / "clouds" / "0_3.ply"))["vertex"]
    assert [p.name for p in vertices.properties] == ["x", "y", "z", "red", "green", "blue"]
    points = np.column_stack([vertices["x"], vertices["y"], vertices["z"]])
    assert len(points) > 50
    centre = points.mean(axis=0)
    assert np.linalg.norm(centre) == pytest.approx(estimate["details"]["object_distance"], abs=0.1)
    assert np.linalg.norm(points - centre, axis=1).max() < 0.2, "the points of one 20 cm object"


def test_the_report_gives_each_view_its_mask_iou_and_the_mean_and_worst(bag, saved):
    run, out = saved
    report = json.loads((out / "report" / "report.json").read_text())
    figures = report["mask_iou"]
    per_view = {int(k): v for k, v in figures["per_view"].items()}
    used = sorted({view for estimate in run.estimates for view in estimate["views"]})
    assert sorted(per_view) == used and figures["views"] == 3 and figures["true_mask_topic"] == TRUE_MASK_TOPIC
    assert figures["mean"] == pytest.approx(np.mean(list(per_view.values())))
    assert figures["worst"] == min(per_view.values()) and 0.0 < figures["worst"] <= figures["mean"] <= 1.0
    truth = read_true_masks(bag, TRUE_MASK_TOPIC, read_bag_views(bag, IMAGE_TOPIC), set(used), 0.01)
    for view_id, value in per_view.items():  # the report scores the very masks that were saved
        mask = cv2.imread(str(out / "saved" / "views" / f"{view_id}_mask.png"), cv2.IMREAD_UNCHANGED) > 0
        assert value == pytest.approx(mask_iou(mask, truth[view_id]))
    assert f"worst {figures['worst']:.3f} (3 views)" in (out / "report" / "report.md").read_text()


def test_replay_mode_refuses_to_save_views_before_anything_runs(bag, tmp_path, capsys):
    code = evaluate_bag_command.main([str(bag), "--mode", "replay", "--save-views", str(tmp_path / "v"),
                                      "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and "--save-views needs --mode offline" in err and not (tmp_path / "v").exists()
