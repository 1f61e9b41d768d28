"""The flight recorder against a real kill: the node as a subprocess, SIGKILLed after 3 captures, restarted.

The node (``python -m idpose_ros.node.process``, the tiny random Zero-1-to-3 and the reduced
solver of test_estimator_node.py) keeps 3 views on ``~/capture`` and estimates them; then it is killed
with SIGKILL and started again on the same ``record_dir``. It says in its log and on /diagnostics that
it resumed the 3 views, and its estimate of them gives the same poses, to the bit, as before the kill
(same seed). A full disk (the process's file size limit) stops the recording with one error and the
estimates go on.
"""
from __future__ import annotations

import resource
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray
from node_harness import FAST_SOLVER, header
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import Image
from std_srvs.srv import Trigger

from idpose_ros.node.diagnostics import STATUS_NAME
from idpose_ros.node.result_publisher import RESULT_QOS
from idpose_ros.recording.log_format import read_recording
from msg_adapters import array_to_image, pose_to_matrix

pytestmark = pytest.mark.slow  # every test here starts a node or a process, or takes seconds

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT = 90.0


class NodeProcess:
    """The estimator in a subprocess under ``namespace``, and a probe node that captures, estimates and listens."""

    def __init__(self, context, wait_for, namespace: str, log: Path, parameters: dict, limit_bytes: int = 0) -> None:
        self.namespace, self.log, self.wait_for = namespace, log, wait_for
        arguments = [f"{name}:={value}" for name, value in parameters.items()]
        command = [sys.executable, "-m", "idpose_ros.node.process", "--ros-args", "-r", f"__ns:={namespace}",
                   *[item for argument in arguments for item in ("-p", argument)]]

        def limit() -> None:  # a disk that fills up after limit_bytes (Python ignores SIGXFSZ: writes fail)
            if limit_bytes:
                resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))

        with log.open("w") as output:
            self.process = subprocess.Popen(command, cwd=ROOT, stdout=output, stderr=subprocess.STDOUT,
                                            preexec_fn=limit)
        self.probe = Node("recorder_probe", namespace=namespace, context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.probe)
        self.status: dict[str, str] = {}
        self.poses: list[PoseArray] = []
        self.probe.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 10)
        self.probe.create_subscription(PoseArray, "idpose_estimator/poses", self.poses.append, RESULT_QOS)
        self.images = self.probe.create_publisher(Image, "image", 10)

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for entry in msg.status:
            if entry.name == STATUS_NAME and entry.hardware_id.startswith(f"{self.namespace}/idpose_estimator ("):
                self.status = {kv.key: kv.value for kv in entry.values}

    def spin_until(self, predicate, what: str):
        def step():
            self.executor.spin_once(timeout_sec=0.05)
            assert self.process.poll() is None, f"the estimator exited:\n{self.log.read_text()}"
            return predicate()
        return self.wait_for(step, what, TIMEOUT)

    def call(self, name: str) -> Trigger.Response:
        client = self.probe.create_client(Trigger, f"idpose_estimator/{name}")
        self.spin_until(client.service_is_ready, f"~/{name}")
        future = client.call_async(Trigger.Request())
        return self.spin_until(future.result, f"the answer of ~/{name}")

    def capture(self, image: Image) -> None:
        self.spin_until(lambda: self.images.get_subscription_count() > 0, "the image subscription")
        self.spin_until(lambda: "images_received" in self.status, "/diagnostics")
        before = int(self.status["images_received"])
        self.images.publish(image)
        self.spin_until(lambda: int(self.status["images_received"]) > before, "the image to arrive")
        answer = self.call("capture")
        assert answer.success, answer.message

    def estimate(self) -> np.ndarray:
        """Poses (k, 4, 4) of an estimate of the buffered views."""
        count = len(self.poses)
        answer = self.call("estimate")
        assert answer.success, answer.message
        self.spin_until(lambda: len(self.poses) > count, "the poses")
        return np.stack([pose_to_matrix(pose) for pose in self.poses[-1].poses])

    def close(self, kill: bool = False) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGKILL if kill else signal.SIGINT)
            self.process.wait(timeout=30)
        self.executor.shutdown()
        self.probe.destroy_node()


@pytest.fixture
def parameters(tiny_model_dir, tmp_path) -> dict:
    return {"model_path": str(tiny_model_dir), "capture_mode": "on_request", "record_dir": str(tmp_path / "rec"),
            "diagnostics_period": 0.2, **FAST_SOLVER}


def views(object_views) -> list[Image]:
    return [array_to_image(np.dstack([rgb, alpha]), "rgba8", header("camera_optical", 50 + k))
            for k, (rgb, alpha) in enumerate(object_views[:3])]


def test_a_node_killed_after_3_captures_resumes_them_and_estimates_the_same_poses(
        ros_context, wait_for, object_views, parameters, tmp_path):
    first = NodeProcess(ros_context, wait_for, "/killed", tmp_path / "first.log", parameters)
    try:
        for image in views(object_views):
            first.capture(image)
        before = first.estimate()  # the same views and seed, without a kill
    finally:
        first.close(kill=True)
    assert first.process.returncode == -signal.SIGKILL

    second = NodeProcess(ros_context, wait_for, "/killed", tmp_path / "second.log", parameters)
    try:
        second.spin_until(lambda: second.status.get("views_buffered") == "3", "the 3 resumed views on /diagnostics")
        assert second.status["recording_resumed"].startswith("3 views from idpose_"), second.status
        after = second.estimate()
    finally:
        second.close()
    log = (tmp_path / "second.log").read_text()
    assert "resumed 3 views from idpose_" in log and "sealed after its last whole record" in log, log
    assert before.shape == (3, 4, 4) and not np.allclose(before[1], np.eye(4))
    np.testing.assert_array_equal(after, before)
    assert second.poses[-1].header.stamp == header("", 50).stamp  # the anchor is the first view captured

    killed, resumed = sorted((tmp_path / "rec").glob("idpose_*.mcap"))
    recording = read_recording(killed)
    assert len(recording.buffered) == 3 and len(recording.results) == 1 and recording.scan.sealed
    assert [view.carried for view in read_recording(resumed).buffered] == [True] * 3
    np.testing.assert_array_equal(
        np.stack([pose_to_matrix(pose) for pose in recording.results[0].result.poses.poses]), before)


def test_a_full_disk_stops_the_recording_with_one_error_and_estimates_go_on(
        ros_context, wait_for, object_views, parameters, tmp_path):
    node = NodeProcess(ros_context, wait_for, "/full_disk", tmp_path / "node.log", parameters,
                       limit_bytes=30_000)  # room for the first view (64 px rgba: 16 KB), not the second
    try:
        for image in views(object_views):
            node.capture(image)
        node.spin_until(lambda: node.status.get("recording", "").startswith("error: recording stopped"),
                        "the recording error on /diagnostics")
        assert node.estimate().shape == (3, 4, 4)
    finally:
        node.close()
    errors = [line for line in (tmp_path / "node.log").read_text().splitlines() if "recording stopped" in line]
    assert len(errors) == 1 and "[ERROR]" in errors[0] and "keeps working without recording" in errors[0], errors
    assert len(read_recording(next((tmp_path / "rec").glob("idpose_*.mcap"))).buffered) == 1
