"""Replays a view set to the estimator node over ROS, as a robot would, and collects what it publishes.

Per view set: set the node's parameters (solver settings, anchor polar angle, object distance,
``capture_mode`` on_request), ``~/reset``, then for each image publish it on the node's ``image``
(or ``image/compressed``) topic and call ``~/capture``; then ``~/estimate``, and read the poses
from ``~/poses`` and the per-view scores and ambiguity flags from ``/diagnostics``, once the status
carries the ``run_id`` that ``~/estimate`` answered. The node runs in
this process (started here, model loaded by the node) or is a running node named by ``node_name``.
"""
from __future__ import annotations

import os
import re
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, QuaternionStamped
from rclpy.executors import MultiThreadedExecutor
from rclpy.logging import LoggingSeverity, set_logger_level
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import qos_profile_sensor_data
from rclpy.time import Time
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from std_msgs.msg import Header
from std_srvs.srv import Trigger

from idpose_core.evaluation.estimator import ViewSetEstimate
from idpose_core.evaluation.picks import PICK_SIZE
from idpose_core.gravity import level_from_optical
from idpose_core.solver import Progress
from idpose_core.view_input import ViewInput
from idpose_ros.node.diagnostics import RUNNING_STATES, STATUS_NAME
from idpose_ros.node.estimator_node import NODE_NAME, RESULT_QOS, EstimatorNode
from idpose_ros.view_decoding import ViewMessages, encode_view
from msg_adapters import matrix_to_pose, pose_to_matrix, stamp_nanoseconds

SERVICE_TIMEOUT = 10.0  # s to wait for a service call, a subscriber or a parameter change
CONNECT_TIMEOUT = 30.0  # s to wait for the node's services to appear (a node may still be starting)
CAPTURE_RETRY = 0.05  # s between two ~/capture attempts while the image is on its way
REPUBLISH_AFTER = 1.0  # s without the node receiving an image before it is published again
INPUTS_SETTLE = 0.1  # s between publishing a view's other inputs and its image (they go on other DDS topics)
IN_PROCESS_DIAGNOSTICS_PERIOD = 0.2  # s, for a node started here
# Node parameters a replay sets besides the solver's; a running node gets its own values back on close().
RUN_ID = re.compile(r"\(run (\d+)\)$")  # how the ~/estimate answer ends: "... (run 7)"
REPLAY_FRAME = "replay_camera"  # frame_id of the replayed views
VIEW_STAMP_STEP_NS = 100_000_000  # replayed views are stamped 0.1 s apart: far more than any input tolerance
REPLAY_PARAMETERS = ("anchor_polar_deg", "object_distance", "capture_mode", "views_per_estimate", "max_views",
                     "anchor_frame")


class ReplayError(RuntimeError):
    """The estimator node refused, failed or did not answer; the message says which and why."""


def _wait(condition: Callable[[], bool], timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise ReplayError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(0.01)


class ReplayEstimator:
    """A ``ViewSetEstimator`` that goes through the estimator node; call ``close()`` when done."""

    def __init__(self, values: dict[str, Any], model_path: str = "", device: str = "auto",
                 precision: str = "auto", node_name: str | None = None, timeout: float = 3600.0,
                 preset: str = "default"):
        """``values``: the node parameters every estimate runs on (``preset`` names where they came from)."""
        self.values, self.timeout = values, timeout
        self._context = rclpy.Context()
        rclpy.init(context=self._context)
        self._executor = MultiThreadedExecutor(num_threads=4, context=self._context)
        self._estimator: EstimatorNode | None = None
        if node_name is None:
            namespace = f"/idpose_evaluate_bag_{os.getpid()}"
            # warnings and errors only, from its first line on: the terminal belongs to the progress bar
            set_logger_level(f"{namespace[1:]}.{NODE_NAME}", LoggingSeverity.WARN)
            self._estimator = EstimatorNode(context=self._context, namespace=namespace, parameter_overrides=[
                Parameter("model_path", value=model_path), Parameter("device", value=device),
                Parameter("precision", value=precision),
                Parameter("diagnostics_period", value=IN_PROCESS_DIAGNOSTICS_PERIOD)])
            self._executor.add_node(self._estimator)
            node_name = self._estimator.get_fully_qualified_name()
        self.node_name = node_name.rstrip("/")
        namespace = self.node_name.rsplit("/", 1)[0]
        self._client = rclpy.create_node("idpose_evaluate_bag", context=self._context, namespace=namespace or "/")
        self._executor.add_node(self._client)
        self._lock = threading.Lock()
        self._poses: PoseArray | None = None
        self._status: dict[str, str] | None = None
        self._inputs = {kind: self._client.create_publisher(kind_type, f"{namespace}/{kind}", 10)
                        for kind, kind_type in (("depth", Image), ("mask", Image), ("camera_info", CameraInfo),
                                                ("camera_orientation", QuaternionStamped))}
        self._publishers = {
            Image: self._client.create_publisher(Image, f"{namespace}/image", qos_profile_sensor_data),
            CompressedImage: self._client.create_publisher(CompressedImage, f"{namespace}/image/compressed",
                                                           qos_profile_sensor_data),
        }
        self._services = {name: self._client.create_client(Trigger, f"{self.node_name}/{name}")
                          for name in ("capture", "estimate", "reset")}
        self._parameters = AsyncParameterClient(self._client, self.node_name)
        self._client.create_subscription(PoseArray, f"{self.node_name}/poses", self._on_poses, RESULT_QOS)
        self._client.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 10)
        self._spinner = threading.Thread(target=self._executor.spin, daemon=True)
        self._spinner.start()
        try:
            for name, client in self._services.items():
                if not client.wait_for_service(timeout_sec=CONNECT_TIMEOUT):
                    raise ReplayError(f"no estimator node answers {self.node_name}/{name} "
                                      f"(waited {CONNECT_TIMEOUT:g} s; is --node its fully qualified name?)")
            if not self._parameters.wait_for_services(timeout_sec=CONNECT_TIMEOUT):
                raise ReplayError(f"the parameter services of {self.node_name} do not answer")
            self._wait_for_status(lambda status: status["state"] not in RUNNING_STATES, self.timeout,
                                  "finish its running estimate")
            model = {"node": self.node_name, **self._get_parameters(("model_path", "device", "precision"))}
            self.description = {"mode": "replay", "model": model, "solver_preset": preset}
            self._restore = {} if self._estimator else self._get_parameters([*self.values, *REPLAY_PARAMETERS])
        except BaseException:
            self.close()
            raise

    # ----- subscriptions ---------------------------------------------------------------------------------------
    def _on_poses(self, msg: PoseArray) -> None:
        with self._lock:
            self._poses = msg

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name == STATUS_NAME and status.hardware_id.startswith(f"{self.node_name} ("):
                with self._lock:
                    self._status = {item.key: item.value for item in status.values}

    def _latest_status(self) -> dict[str, str] | None:
        with self._lock:
            return self._status

    def _wait_for_status(self, done: Callable[[dict[str, str]], bool], timeout: float, what: str,
                         progress: Progress | None = None) -> dict[str, str]:
        """The first /diagnostics status for which ``done`` holds; progress reported on the way. ReplayError
        on timeout."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            status = self._latest_status()
            if status is not None:
                if done(status):
                    return status
                if progress is not None and status["state"] == "estimating":
                    progress(status["stage"], round(float(status["progress_percent"])), 100)
            time.sleep(0.02)
        raise ReplayError(f"the estimator node {self.node_name} did not {what} within {timeout:g} s")

    # ----- services and parameters ---------------------------------------------------------------------------------
    def _call(self, name: str) -> Trigger.Response:
        future = self._services[name].call_async(Trigger.Request())
        _wait(future.done, SERVICE_TIMEOUT, f"{self.node_name}/{name}")
        return future.result()

    def _get_parameters(self, names: Sequence[str]) -> dict[str, Any]:
        future = self._parameters.get_parameters(list(names))
        _wait(future.done, SERVICE_TIMEOUT, f"the parameters of {self.node_name}")
        return {name: parameter_value_to_python(value) for name, value in zip(names, future.result().values)}

    def _set_parameters(self, values: dict[str, Any]) -> None:
        future = self._parameters.set_parameters_atomically([Parameter(k, value=v) for k, v in values.items()])
        _wait(future.done, SERVICE_TIMEOUT, f"the parameters of {self.node_name}")
        result = future.result().result
        if not result.successful:
            raise ReplayError(f"the estimator node refused the parameters: {result.reason}")

    def _publish_inputs(self, view: ViewMessages) -> list[str]:
        """Publish the view's other inputs on the node's topics (gravity as the optical frame's orientation in a
        z-up frame, stamped as the image); returns their kinds."""
        stamp = view.image.header.stamp
        sent = {"depth": view.depth, "mask": view.mask, "camera_info": view.camera_info}
        if view.gravity_up is not None:
            orientation = matrix_to_pose(np.block([[level_from_optical(view.gravity_up), np.zeros((3, 1))],
                                                   [np.zeros((1, 3)), np.ones((1, 1))]])).orientation
            sent["camera_orientation"] = QuaternionStamped(header=Header(stamp=stamp), quaternion=orientation)
        for kind, message in sent.items():
            if message is not None:
                publisher = self._inputs[kind]
                _wait(lambda publisher=publisher: publisher.get_subscription_count() > 0, SERVICE_TIMEOUT,
                      f"the estimator to subscribe to {publisher.topic_name}")
                publisher.publish(message)
        return [kind for kind, message in sent.items() if message is not None]

    def _capture(self, view: ViewMessages) -> None:
        """Publish one view (its other inputs first, and let them arrive) and keep it with ~/capture, publishing
        the image again if it got lost on the way. ReplayError when the node kept it without an input."""
        message = view.image
        if self._publish_inputs(view):
            time.sleep(INPUTS_SETTLE)
        publisher = self._publishers[type(message)]
        _wait(lambda: publisher.get_subscription_count() > 0, SERVICE_TIMEOUT,
              f"the estimator to subscribe to {publisher.topic_name}")
        deadline = time.monotonic() + SERVICE_TIMEOUT
        while time.monotonic() < deadline:
            publisher.publish(message)
            republish_at = time.monotonic() + REPUBLISH_AFTER
            while time.monotonic() < republish_at:
                response = self._call("capture")
                if response.success:
                    if view.gravity_up is not None and "gravity" not in response.message:
                        raise ReplayError(f"{self.node_name} kept a view without its gravity: {response.message}")
                    return
                time.sleep(CAPTURE_RETRY)
        raise ReplayError(f"{self.node_name}/capture kept refusing the image published on {publisher.topic_name}: "
                          f"{response.message}")

    # ----- one view set ---------------------------------------------------------------------------------------------
    def __call__(self, views: Sequence[ViewInput], anchor_polar_deg: float, object_distance: float,
                 progress: Progress | None = None) -> ViewSetEstimate:
        start = self._client.get_clock().now().nanoseconds
        encoded = [encode_view(view, Time(nanoseconds=start + k * VIEW_STAMP_STEP_NS).to_msg(), REPLAY_FRAME)
                   for k, view in enumerate(views)]
        messages = [view.image for view in encoded]
        self._set_parameters({**self.values, "anchor_polar_deg": float(anchor_polar_deg),
                              "object_distance": float(object_distance), "capture_mode": "on_request",
                              "views_per_estimate": 0, "max_views": PICK_SIZE, "anchor_frame": ""})
        self._call("reset")
        for view in encoded:
            self._capture(view)
        with self._lock:
            self._poses = None
        response = self._call("estimate")
        run = RUN_ID.search(response.message)
        if not response.success or run is None:
            raise ReplayError(f"{self.node_name}/estimate refused: {response.message}")
        status = self._wait_for_status(
            lambda status: status["run_id"] == run[1] and status["state"] not in RUNNING_STATES,
            self.timeout, f"finish estimate run {run[1]}", progress)
        if status["state"] == "failed" or status["last_error"]:
            raise ReplayError(f"the estimator node's run {run[1]} failed: {status['last_error'] or status['model']}")
        anchor_stamp = stamp_nanoseconds(messages[0].header.stamp)

        def published() -> bool:  # the poses go out before the status says the run is over
            with self._lock:
                return (self._poses is not None and len(self._poses.poses) == len(messages)
                        and stamp_nanoseconds(self._poses.header.stamp) == anchor_stamp)

        _wait(published, SERVICE_TIMEOUT, f"the poses of run {run[1]} on {self.node_name}/poses")
        with self._lock:
            poses = np.stack([pose_to_matrix(pose) for pose in self._poses.poses])
        views = range(1, len(messages))
        return ViewSetEstimate(
            poses=poses,
            scores=np.array([float(status[f"view_{k}_score"]) for k in views]),
            ambiguous=np.array([status[f"view_{k}_ambiguous"] == "true" for k in views]),
            seconds=float(status["last_run_seconds"]),
        )

    def close(self) -> None:
        """Give a running node its parameters back, or stop the node started here; then leave ROS."""
        if getattr(self, "_restore", None):
            try:
                self._set_parameters(self._restore)
            except ReplayError as err:
                self._client.get_logger().warning(f"could not restore the parameters of {self.node_name}: {err}")
        if self._estimator is not None:
            self._estimator.stop()
        self._executor.shutdown(timeout_sec=1.0)
        for node in (self._estimator, getattr(self, "_client", None)):
            if node is not None:
                node.destroy_node()
        rclpy.try_shutdown(context=self._context)
