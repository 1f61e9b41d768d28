"""The in-process estimator node and its probe, shared by the node tests (the ``harness`` fixture in conftest.py
makes them): a probe node publishes images, calls services and subscribes to the outputs, over ROS only.

Reduced for speed: the tiny random Zero-1-to-3 on views preprocessed at 32 px (its native size), solver with
2 azimuth candidates, probe batch 1, no adjustment steps, keep 1, 2 refinement steps and 1 runner-up step per
view (the paper: 8, 16, 10, 5, 600, 100).
"""
from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import cv2
import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray
from rcl_interfaces.msg import Log
from rclpy.action import ActionClient
from rclpy.action.client import ClientGoalHandle
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Header
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from idpose_interfaces.action import EstimatePoses
from idpose_ros.node.estimator_node import SERVICE_QOS, EstimatorNode
from idpose_ros.node.result_publisher import RESULT_QOS
from msg_adapters import array_to_image

TIMEOUT = 60.0
FAST_SOLVER = dict(azimuth_candidates=2, probe_batch=1, adjust_steps=0, keep_top=1, refine_steps_per_view=2,
                   average_last=1, runner_up_steps=1, image_size=32, min_view_interval=0.0)


def header(frame_id: str, sec: int) -> Header:
    return Header(frame_id=frame_id, stamp=Time(sec=sec, nanosec=7))


def compressed(rgb: np.ndarray, codec: str, head: Header) -> CompressedImage:
    ok, data = cv2.imencode(f".{codec}", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    assert ok
    return CompressedImage(header=head, format=f"rgb8; {codec} compressed bgr8", data=data.tobytes())


def mixed_encodings(views) -> list[Image | CompressedImage]:
    """The four views as rgba8 (alpha kept, the anchor), bgr8, png and jpeg: the encodings a robot sends."""
    (rgb0, alpha0), (rgb1, _), (rgb2, _), (rgb3, _) = views
    return [
        array_to_image(np.dstack([rgb0, alpha0]), "rgba8", header("anchor_cam", 42)),
        array_to_image(np.ascontiguousarray(rgb1[..., ::-1]), "bgr8", header("cam", 43)),
        compressed(rgb2, "png", header("cam", 44)),
        compressed(rgb3, "jpg", header("cam", 45)),
    ]


class Harness:
    """An EstimatorNode and a probe node on one multi-threaded executor spinning in a thread."""

    def __init__(self, context, wait_for: Callable[..., Any], namespace: str, **overrides: Any) -> None:
        self.wait_for = wait_for
        self.node = EstimatorNode(context=context, namespace=namespace,
                                  parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()])
        self.probe = Node("probe", namespace=namespace, context=context)
        self.images = self.probe.create_publisher(Image, "image", 10)
        self.compressed = self.probe.create_publisher(CompressedImage, "image/compressed", 10)
        self.poses: list[PoseArray] = []
        self.markers: list[MarkerArray] = []
        self.views: list[Image] = []
        self.logs: list[Log] = []
        self.diagnostics: list[DiagnosticArray] = []
        for kind, topic, sink in ((PoseArray, "idpose_estimator/poses", self.poses),
                                  (MarkerArray, "idpose_estimator/markers", self.markers),
                                  (Image, "idpose_estimator/views", self.views)):
            self.probe.create_subscription(kind, topic, sink.append, RESULT_QOS)
        self.probe.create_subscription(Log, "/rosout", self._on_log,  # latched: logs from before the probe joined
                                       QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.probe.create_subscription(DiagnosticArray, "/diagnostics", self.diagnostics.append, 10)
        self.clients = {name: self.probe.create_client(Trigger, f"idpose_estimator/{name}")
                        for name in ("capture", "estimate", "cancel", "reset")}
        self.executor = MultiThreadedExecutor(num_threads=4, context=context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.probe)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        self.wait_for(lambda: self.images.get_subscription_count() and self.compressed.get_subscription_count(),
                 "the node's image subscriptions")

    def _on_log(self, entry: Log) -> None:
        if entry.name.endswith("idpose_estimator"):
            self.logs.append(entry)

    def logged(self, text: str) -> list[str]:
        return [entry.msg for entry in self.logs if text in entry.msg]

    def call(self, service: str) -> Trigger.Response:
        client = self.clients[service]
        assert client.wait_for_service(TIMEOUT), service
        future = client.call_async(Trigger.Request())
        return self.wait_for(future.result, f"the answer of ~/{service}")

    def send(self, msg: Image | CompressedImage) -> None:
        (self.images if isinstance(msg, Image) else self.compressed).publish(msg)

    def send_view(self, msg: Image | CompressedImage) -> None:
        """Publish one image and wait until the node has kept it as a view."""
        before = self.node.status().views_buffered
        self.send(msg)
        self.wait_for(lambda: self.node.status().views_buffered == before + 1, "the view to be buffered")

    def state(self) -> str:
        return self.node.status().state

    def close(self) -> None:
        assert self.node.stop(timeout=10.0)
        self.executor.shutdown(timeout_sec=2.0)
        self.thread.join(5.0)
        self.probe.destroy_node()
        self.node.destroy_node()


class ActionProbe:
    """An ActionClient for the harness's node, recording every feedback message per goal."""

    def __init__(self, h: Any) -> None:
        self.h = h
        self.client = ActionClient(h.probe, EstimatePoses, "idpose_estimator/estimate_poses",
                                   goal_service_qos_profile=SERVICE_QOS, result_service_qos_profile=SERVICE_QOS,
                                   cancel_service_qos_profile=SERVICE_QOS)
        assert self.client.wait_for_server(TIMEOUT), "the action server"
        self.feedback: list[EstimatePoses.Feedback] = []
        self._lock = threading.Lock()

    def _on_feedback(self, message: Any) -> None:
        with self._lock:
            self.feedback.append(message.feedback)

    def send(self, images: list[Image] | None = None, preset: str = "") -> ClientGoalHandle:
        future = self.client.send_goal_async(EstimatePoses.Goal(images=images or [], preset=preset),
                                             feedback_callback=self._on_feedback)
        handle = self.h.wait_for(future.result, "the goal response")
        assert handle.accepted, "every goal is accepted; one that cannot run ends at once with its reason"
        return handle

    def result(self, handle: ClientGoalHandle, timeout: float = TIMEOUT) -> tuple[int, EstimatePoses.Result]:
        """(goal status, result) once the goal has ended."""
        future = handle.get_result_async()
        response = self.h.wait_for(future.result, "the goal result", timeout=timeout)
        return response.status, response.result

    def run(self, images: list[Image] | None = None, preset: str = "") -> tuple[int, EstimatePoses.Result]:
        return self.result(self.send(images, preset))
