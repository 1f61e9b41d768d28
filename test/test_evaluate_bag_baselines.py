"""evaluate_bag with --baselines: COLMAP and the feature baseline run on the same views of every estimate, with
the bag's camera_info, and get their rows, convergence counts and seconds in report.md and report.json.

The ID-Pose estimator is a stub here (every view at the anchor's pose): only the baselines' wiring is under
test; test_baselines.py checks their accuracy and test_evaluate_bag.py ID-Pose's.
"""
import json

import numpy as np
import pytest

from idpose_core.baselines import CONVERGED, FAILED, FEWER
from idpose_core.evaluation.estimator import ViewSetEstimate
from idpose_core.evaluation.protocol import EvaluationProtocol
from idpose_ros import cli_options, evaluate_bag
from idpose_ros.dataset.synthetic_bag import IMAGE_TOPIC, SyntheticBagOptions, make_bag
from idpose_ros.evaluation import bag_evaluation
from idpose_ros.evaluation.bag_report import write_report
from idpose_ros.evaluation.bag_views import ExtraTopics, default_camera_info_topic
from idpose_ros.evaluation.estimators import EstimatorOptions
from idpose_ros.evaluation.ground_truth import GroundTruthOptions, read_views

SIZE, VIEWS = 256, 6


class AnchorStub:
    """A ViewSetEstimator that puts every view at the anchor: cheap, and nothing like the baselines' answers."""

    values = EstimatorOptions(preset="fast").node_values()
    description = {"mode": "offline", "model": {"predictor": "stub"}, "solver_preset": "fast"}

    def __call__(self, messages, anchor_polar_deg, object_distance, progress=None) -> ViewSetEstimate:
        n = len(messages)
        return ViewSetEstimate(np.repeat(np.eye(4)[None], n, axis=0), np.zeros(n - 1), np.zeros(n - 1, bool), 0.01)

    def close(self) -> None:
        pass


@pytest.fixture(scope="module")
def textured_bag(tmp_path_factory):
    path = tmp_path_factory.mktemp("baselines") / "bag"
    make_bag(path, SyntheticBagOptions("mcap", "textured", "numbered_cube", views=VIEWS, seed=2, size=SIZE))
    return path


@pytest.fixture(scope="module")
def run(textured_bag):
    return bag_evaluation.evaluate_bag(textured_bag, AnchorStub(), GroundTruthOptions(IMAGE_TOPIC),
                                     EvaluationProtocol(samples=1, seed=0, view_counts=(2, 4)), show_progress=False,
                                     baselines=("colmap", "features"))


def test_both_baselines_score_the_same_pairs_as_id_pose(run):
    pairs = [(r["sample"], r["n"], r["anchor_view"], r["view"]) for r in run.records]
    assert len(pairs) == 1 + 3
    for name in ("colmap", "features"):
        records, rows = run.baseline_records[name], run.baseline_estimates[name]
        assert [(r["sample"], r["n"], r["anchor_view"], r["view"]) for r in records] == pairs
        assert [row["views"] for row in rows] == [e["views"] for e in run.estimates]
        assert all(row["status"] in (CONVERGED, FEWER, FAILED) and row["seconds"] > 0 for row in rows)
        for row in rows:  # the registered views are what the status says
            placed = len(row["registered"])
            assert row["registered"][0] == row["views"][0]
            assert row["status"] == (CONVERGED if placed == row["n"] else FAILED if placed == 1 else FEWER)
        assert all(np.isfinite(r["rot_err_deg"]) and isinstance(r["registered"], bool) for r in records)


def test_the_report_has_a_row_and_convergence_counts_per_baseline(run, tmp_path):
    table = write_report(tmp_path, run)
    assert "| COLMAP | all |" in table and "| SIFT + essential matrix | all |" in table
    markdown = (tmp_path / "report.md").read_text()
    assert "## Baselines: convergence and time" in markdown and "| ID-Pose (full) | all | — (2 estimates) |" in markdown
    report = json.loads((tmp_path / "report.json").read_text())
    assert set(report["baselines"]) == {"colmap", "features"}
    for baseline in report["baselines"].values():
        convergence = baseline["convergence"]
        assert convergence["all"]["estimates"] == 2 and f"| {baseline['title']} | all | " in markdown
        assert f"{convergence['all']['converged']} + {convergence['all']['fewer']} of 2" in markdown
        assert baseline["aggregates"]["all"]["pairs"] == 4 and len(baseline["pairs"]) == 4
    # the intrinsics are the bag's camera_info beside its image topic
    assert report["intrinsics"] == "the CameraInfo on /camera/camera_info nearest in time to each anchor view"


def test_without_baselines_the_report_is_unchanged(textured_bag, tmp_path):
    plain = bag_evaluation.evaluate_bag(textured_bag, AnchorStub(), GroundTruthOptions(IMAGE_TOPIC),
                                      EvaluationProtocol(samples=1, seed=0, view_counts=(2,)), show_progress=False)
    assert plain.baseline_records == {}
    write_report(tmp_path, plain)
    assert "baselines" not in json.loads((tmp_path / "report.json").read_text())
    assert "Baselines" not in (tmp_path / "report.md").read_text()


def test_camera_info_topic_default_missing_and_unknown_baselines(textured_bag):
    assert default_camera_info_topic("/camera/image_raw") == "/camera/camera_info"
    assert default_camera_info_topic("/cam/color/image_raw/compressed") == "/cam/color/camera_info"
    views = read_views(textured_bag, GroundTruthOptions(IMAGE_TOPIC,
                                                                     extras=ExtraTopics(camera_info_topic="/none")))
    assert views.pool and not any("camera_info" in sources.messages for sources in views.extras.values())
    with pytest.raises(ValueError, match="unknown baseline 'relpose'"):
        bag_evaluation.evaluate_bag(textured_bag, AnchorStub(), GroundTruthOptions(IMAGE_TOPIC), views=views,
                                  baselines=("relpose",), show_progress=False)
    args, _ = evaluate_bag.parse_args([str(textured_bag), "--baselines", "colmap", "features",
                                    "--camera-info-topic", "/cam/camera_info"])
    assert args.baselines == ["colmap", "features"]
    assert cli_options.ground_truth_options(args).inputs.camera_info_topic == "/cam/camera_info"
    with pytest.raises(SystemExit):
        evaluate_bag.parse_args([str(textured_bag), "--baselines", "relpose"])
