"""evaluate_bag on a flight recording: the node's own estimate ("as estimated live") beside a fresh one.

The recording is written by ``FlightRecorder`` as the node writes it: 4 views of a synthetic bag kept
with their images as received, the bag's true camera poses (PoseStamped) recorded beside them, and
one published result, estimated by the node's pipeline (the tiny random Zero-1-to-3, a reduced
solver) on the anchor geometry the evaluation gives every estimate. evaluate_bag then reads the
recording directly and re-estimates the same views with the same model, seed and settings: the
fresh row must equal the live row, pair for pair (up to the PoseArray's quaternion rounding).
Nothing here checks accuracy (the model is random).
"""
from __future__ import annotations

import json

import numpy as np
from geometry_msgs.msg import PoseStamped
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import Image
from std_msgs.msg import Header

from idpose_core.evaluation.object_frame import object_frame_c2w
from idpose_core.evaluation.protocol import OBJECT_CENTER, WORLD_UP
from idpose_core.evaluation.run import anchor_geometry
from idpose_core.model_loading import load_predictor
from idpose_core.pipeline import estimate_view_poses
from idpose_ros import evaluate_bag
from idpose_ros.dataset.synthetic_bag import IMAGE_TOPIC, POSE_TOPIC, SyntheticBagOptions, make_bag
from idpose_ros.estimate_result import result_message
from idpose_ros.evaluation.bag_io import open_bag
from idpose_ros.evaluation.estimators import EstimatorOptions
from idpose_ros.evaluation.recording import LIVE_METHOD
from idpose_ros.node.flight_recorder import FlightRecorder, restored_view
from idpose_ros.node.parameters import pipeline_settings
from idpose_ros.view_decoding import ViewMessages
from msg_adapters import pose_to_matrix

SOLVER = ("azimuth_candidates=2", "probe_batch=1", "adjust_steps=0", "keep_top=1", "refine_steps_per_view=2",
          "average_last=1", "runner_up_steps=1")
VIEWS = 4


def test_a_recording_is_evaluated_live_beside_a_fresh_estimate(tmp_path, tiny_model_dir, capsys):
    bag = make_bag(tmp_path / "bag", SyntheticBagOptions(views=VIEWS, seed=3, size=64))
    with open_bag(bag) as reader:
        images = [deserialize_message(raw, Image) for _, _, raw in
                  reader.messages(connections=[c for c in reader.connections if c.topic == IMAGE_TOPIC])]
        truths = [deserialize_message(raw, PoseStamped) for _, _, raw in
                  reader.messages(connections=[c for c in reader.connections if c.topic == POSE_TOPIC])]

    kept = []
    recorder = FlightRecorder(str(tmp_path / "rec"), 10**9, lambda: list(kept), print, print)
    recorder.start(False, {"node": "/test"})
    for image, truth in zip(images, truths):
        kept.append(restored_view(ViewMessages(image)))
        recorder.view_kept(len(kept), kept[-1])
        recorder.other(POSE_TOPIC, truth)
    true_c2w = object_frame_c2w(np.stack([pose_to_matrix(truth.pose) for truth in truths]), OBJECT_CENTER, WORLD_UP)
    polar, distance = anchor_geometry(true_c2w)
    values = {**EstimatorOptions(preset="fast", solver_params=SOLVER, image_size=32).node_values(),
              "anchor_polar_deg": polar, "object_distance": distance}
    predictor = load_predictor(str(tiny_model_dir), "cpu", "float32")
    result = estimate_view_poses(predictor, [view.input for view in kept], pipeline_settings(values))
    headers = [Header(frame_id=view.frame_id, stamp=view.stamp) for view in kept]
    recorder.result(result_message(result, headers, kept[0].frame_id, 1, 1.5), values, kept)
    recorder.close()
    (recording,) = (tmp_path / "rec").glob("idpose_*.mcap")

    out = tmp_path / "report"
    code = evaluate_bag.main([str(recording), "--gt-topic", POSE_TOPIC, "--model-path", str(tiny_model_dir),
                              "--device", "cpu", "--preset", "fast", *[f"--solver-param={p}" for p in SOLVER],
                              "--image-size", "32", "--out", str(out)])
    printed = capsys.readouterr().out
    assert code == 0, printed
    report = json.loads((out / "report.json").read_text())
    live = report["baselines"][LIVE_METHOD]
    fresh_pairs, live_pairs = report["pairs"], live["pairs"]
    assert len(fresh_pairs) == len(live_pairs) == VIEWS - 1
    for fresh, again in zip(fresh_pairs, live_pairs):
        assert fresh["view"] == again["view"]
        # the live poses went through the PoseArray's quaternions: equal up to that rounding
        assert abs(fresh["rot_err_deg"] - again["rot_err_deg"]) < 1e-6, (fresh, again)
        assert abs(fresh["pos_err"] - again["pos_err"]) < 1e-6, (fresh, again)
    assert f"| {LIVE_METHOD} | all |" in printed or LIVE_METHOD in (out / "report.md").read_text()
