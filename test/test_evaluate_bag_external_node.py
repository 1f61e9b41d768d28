"""evaluate_bag --mode replay against an estimator node running in its own process, with a real model.

The node is started as a user starts it (its module's entry point with --ros-args, in a namespace)
with the tiny random Zero-1-to-3 from ``model_path``; evaluate_bag connects to it by name. The same
model in offline mode must give the same numbers, and the node gets its own parameters back. Reduced for
speed: 32 px views, one 2-view set, 2 azimuth candidates, 1 probe sample, no adjustment, 2 refinement steps.
"""
import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient

from idpose_ros import evaluate_bag

pytestmark = pytest.mark.slow  # every test here starts a node or a process, or takes seconds

DEMO_BAG = Path(__file__).resolve().parents[1] / "data" / "demo_bags" / "duck"
NAMESPACE = f"/evaluate_bag_test_{os.getpid()}"
TINY_SOLVER = ["azimuth_candidates=2", "probe_batch=1", "adjust_steps=0", "keep_top=1",
               "refine_steps_per_view=2", "average_last=1"]


@pytest.fixture
def running_node(tiny_model_dir, wait_for):
    """The estimator in a subprocess, in a namespace of its own; yields its fully qualified name."""
    process = subprocess.Popen(
        [sys.executable, "-m", "idpose_ros.node.process", "--ros-args", "-r", f"__ns:={NAMESPACE}",
         "-p", f"model_path:={tiny_model_dir}", "-p", "device:=cpu", "-p", "diagnostics_period:=0.2"],
        stderr=subprocess.PIPE, text=True)
    lines: list[str] = []
    threading.Thread(target=lambda: lines.extend(process.stderr), daemon=True).start()
    try:
        wait_for(lambda: any("idpose_estimator up" in line for line in lines) or process.poll() is not None,
                 "the estimator node to start", timeout=120)
        assert process.poll() is None, "".join(lines)
        yield f"{NAMESPACE}/idpose_estimator"
    finally:
        process.terminate()
        process.wait(timeout=30)


def test_replay_to_a_running_node_agrees_with_offline(tmp_path, running_node, tiny_model_dir, ros_context):
    common = [str(DEMO_BAG), "--samples", "1", "--seed", "2", "--n", "2", "--preset", "fast", "--device", "cpu",
              "--image-size", "32", "--model-path", str(tiny_model_dir)]
    common += [x for item in TINY_SOLVER for x in ("--solver-param", item)]
    assert evaluate_bag.main([*common, "--mode", "replay", "--node", running_node, "--timeout", "300",
                              "--out", str(tmp_path / "replay")]) == 0
    assert evaluate_bag.main([*common, "--mode", "offline", "--out", str(tmp_path / "offline")]) == 0
    replay, offline = (json.loads((tmp_path / mode / "report.json").read_text()) for mode in ("replay", "offline"))
    assert replay["model"]["node"] == running_node and replay["model"]["model_path"] == str(tiny_model_dir)
    assert replay["picks"] == offline["picks"]
    (a,), (b,) = offline["pairs"], replay["pairs"]
    assert (a["anchor_view"], a["view"]) == (b["anchor_view"], b["view"])
    assert a["pred_rel_sph"] == pytest.approx(b["pred_rel_sph"], abs=1e-9)
    assert a["rot_err_deg"] == pytest.approx(b["rot_err_deg"], abs=1e-6)
    assert a["pos_err"] == pytest.approx(b["pos_err"], abs=1e-9)
    assert a["score"] == pytest.approx(b["score"], rel=1e-5) and a["ambiguous"] == b["ambiguous"]
    # the node got its own parameters back
    client_node = rclpy.create_node("parameter_check", context=ros_context)
    try:
        client = AsyncParameterClient(client_node, running_node)
        assert client.wait_for_services(timeout_sec=30)
        future = client.get_parameters(["capture_mode", "refine_steps_per_view", "image_size"])
        executor = SingleThreadedExecutor(context=ros_context)
        executor.add_node(client_node)
        executor.spin_until_future_complete(future, timeout_sec=30)
        assert [parameter_value_to_python(v) for v in future.result().values] == ["auto", 600, 256]
    finally:
        client_node.destroy_node()


def test_a_wrong_node_name_is_a_clear_error(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("idpose_ros.evaluation.replay.CONNECT_TIMEOUT", 1.0)
    code = evaluate_bag.main([str(DEMO_BAG), "--mode", "replay", "--node", "/no_such/idpose_estimator",
                              "--out", str(tmp_path)])
    assert code == 2
    assert "no estimator node serves /no_such/idpose_estimator/estimate_poses" in capsys.readouterr().err
