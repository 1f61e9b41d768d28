"""evaluate_bag on a flight recording: the node's own estimate ("as estimated live") beside a fresh one.

The recording is written by ``FlightRecorder`` as the node writes it: 4 views of a synthetic bag kept
with their images as received, the bag's true camera poses (PoseStamped) recorded beside them, and
one published result, estimated by the node's pipeline (the tiny random Zero-1-to-3, a reduced
solver) on the anchor geometry the evaluation gives every estimate. evaluate_bag then reads the
recording directly and re-estimates the same views with the same model, seed and settings: the
fresh row must equal the live row, pair for pair (up to the PoseArray's quaternion rounding).
evaluate_dataset takes a folder of two such recordings and must give the same, on Ray workers.
Nothing here checks accuracy (the model is random).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import Image
from std_msgs.msg import Header

from idpose_core.evaluation.object_frame import object_frame_c2w
from idpose_core.evaluation.protocol import OBJECT_CENTER, WORLD_UP
from idpose_core.evaluation.run import anchor_geometry
from idpose_core.model_loading import load_predictor
from idpose_core.pipeline import estimate_view_poses
from idpose_ros import evaluate_bag, evaluate_dataset
from idpose_ros.dataset.synthetic_bag import IMAGE_TOPIC, POSE_TOPIC, SyntheticBagOptions, make_bag
from idpose_ros.estimate_result import result_message
from idpose_ros.evaluation.bag_io import open_bag
from idpose_ros.evaluation.estimators import EstimatorOptions
from idpose_ros.evaluation.recording import LIVE_METHOD
from idpose_ros.node.flight_recorder import FlightRecorder, restored_view
from idpose_ros.node.parameters import pipeline_settings
from idpose_ros.view_decoding import ViewMessages
from msg_adapters import pose_to_matrix

pytestmark = pytest.mark.slow  # every test here starts a node or a process, or takes seconds

SOLVER = ("azimuth_candidates=2", "probe_batch=1", "adjust_steps=0", "keep_top=1", "refine_steps_per_view=2",
          "average_last=1", "runner_up_steps=1")
VIEWS = 4


def record_session(bag_folder: Path, record_dir: Path, model_dir: Path, seed: int) -> Path:
    """A recording as the node writes it: the views of a synthetic bag (``seed``) kept with their true poses,
    then one published result of the node's pipeline on them; the recording's path."""
    bag = make_bag(bag_folder, SyntheticBagOptions(views=VIEWS, seed=seed, size=64))
    with open_bag(bag) as reader:
        images = [deserialize_message(raw, Image) for _, _, raw in
                  reader.messages(connections=[c for c in reader.connections if c.topic == IMAGE_TOPIC])]
        truths = [deserialize_message(raw, PoseStamped) for _, _, raw in
                  reader.messages(connections=[c for c in reader.connections if c.topic == POSE_TOPIC])]
    before = set(record_dir.glob("idpose_*.mcap"))
    kept = []
    recorder = FlightRecorder(str(record_dir), 10**9, lambda: list(kept), print, print)
    recorder.start(False, {"node": "/test"})
    for image, truth in zip(images, truths):
        kept.append(restored_view(ViewMessages(image)))
        recorder.view_kept(len(kept), kept[-1])
        recorder.other(POSE_TOPIC, truth)
    true_c2w = object_frame_c2w(np.stack([pose_to_matrix(truth.pose) for truth in truths]), OBJECT_CENTER, WORLD_UP)
    polar, distance = anchor_geometry(true_c2w)
    values = {**EstimatorOptions(preset="fast", solver_params=SOLVER, image_size=32).node_values(),
              "anchor_polar_deg": polar, "object_distance": distance}
    predictor = load_predictor(str(model_dir), "cpu", "float32")
    result = estimate_view_poses(predictor, [view.input for view in kept], pipeline_settings(values))
    headers = [Header(frame_id=view.frame_id, stamp=view.stamp) for view in kept]
    recorder.result(result_message(result, headers, kept[0].frame_id, 1, 1.5), values, kept)
    recorder.close()
    (recording,) = set(record_dir.glob("idpose_*.mcap")) - before
    return recording


def estimator_arguments(model_dir: Path) -> list[str]:
    """The evaluators' options for the model and settings ``record_session`` estimated with."""
    return ["--model-path", str(model_dir), "--device", "cpu", "--preset", "fast",
            *[f"--solver-param={p}" for p in SOLVER], "--image-size", "32"]


def same_pairs(fresh_pairs: list[dict], live_pairs: list[dict]) -> None:
    """The fresh estimate's pairs equal the published result's (up to the PoseArray's quaternion rounding)."""
    assert len(fresh_pairs) == len(live_pairs)
    for fresh, again in zip(fresh_pairs, live_pairs):
        assert fresh["view"] == again["view"]
        assert abs(fresh["rot_err_deg"] - again["rot_err_deg"]) < 1e-6, (fresh, again)
        assert abs(fresh["pos_err"] - again["pos_err"]) < 1e-6, (fresh, again)


def test_a_recording_is_evaluated_live_beside_a_fresh_estimate(tmp_path, tiny_model_dir, capsys):
    recording = record_session(tmp_path / "bag", tmp_path / "rec", tiny_model_dir, seed=3)

    out = tmp_path / "report"
    code = evaluate_bag.main([str(recording), "--gt-topic", POSE_TOPIC, *estimator_arguments(tiny_model_dir),
                              "--out", str(out)])
    printed = capsys.readouterr().out
    assert code == 0, printed
    report = json.loads((out / "report.json").read_text())
    live_pairs = report["baselines"][LIVE_METHOD]["pairs"]
    assert len(live_pairs) == VIEWS - 1
    same_pairs(report["pairs"], live_pairs)
    assert f"| {LIVE_METHOD} | all |" in printed or LIVE_METHOD in (out / "report.md").read_text()


def test_a_folder_of_recordings_is_evaluated_as_a_data_set(tmp_path, tiny_model_dir):
    """evaluate_dataset on a record_dir holding two sessions' recordings: one estimate per recorded result,
    estimated again on a Ray worker and equal to the published result; the report aggregates both rows."""
    folder = tmp_path / "record_dir"
    recordings = [record_session(tmp_path / f"bag{seed}", folder, tiny_model_dir, seed) for seed in (3, 4)]
    out = tmp_path / "dataset"
    code = evaluate_dataset.main([str(folder), "--gt-topic", POSE_TOPIC, *estimator_arguments(tiny_model_dir),
                                  "--workers", "1", "--out", str(out)])
    assert code == 0
    lines = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    assert sorted(line["input"] for line in lines) == sorted(str(path.resolve()) for path in recordings)
    for line in lines:
        assert (line["kind"], line["status"], line["n"]) == ("recording", "ok", VIEWS)
        same_pairs(line["pairs"], line["baselines"][LIVE_METHOD]["pairs"])
    report = json.loads((out / "report.json").read_text())
    assert report["estimates"] == {"planned": 2, "succeeded": 2, "failed": 0, "missing": 0}
    scores = report["datasets"][folder.name]
    fresh, live = scores["aggregates"]["all"], scores["baselines"][LIVE_METHOD]["all"]
    assert fresh["pairs"] == live["pairs"] == 2 * (VIEWS - 1)
    assert abs(fresh["mean_rot_err_deg"] - live["mean_rot_err_deg"]) < 1e-6
    assert f"| {LIVE_METHOD} | {VIEWS} |" in (out / "report.md").read_text()
