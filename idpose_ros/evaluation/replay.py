"""Replays a view set to the estimator node over ROS, as a robot would, through its ``EstimatePoses`` action.

Per view set: set the node's parameters that shape the estimate (solver settings, anchor polar angle,
object distance), publish each view's other inputs (depth, mask, CameraInfo, gravity as the camera's
orientation) on the node's topics stamped as its image, then send the images as one goal and read the
typed result: poses, per-view scores and ambiguity, and the same details an offline estimate reports
(``idpose_ros.estimate_result``). A view read from a bag goes out as its messages were recorded (compressed
images stay compressed, 16UC1 depth stays 16UC1), restamped so the node matches them as one view. The node
runs in this process (started here, model loaded by the node) or is a running node named by ``node_name``.
"""
from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import rclpy
from builtin_interfaces.msg import Time as TimeMsg
from geometry_msgs.msg import PoseStamped, QuaternionStamped
from rclpy.action import ActionClient
from rclpy.executors import MultiThreadedExecutor
from rclpy.logging import LoggingSeverity, set_logger_level
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.time import Time
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

from idpose_core.evaluation.estimator import ViewSetEstimate
from idpose_core.gravity import level_from_optical
from idpose_core.noise_predictor import NoisePredictor
from idpose_core.solver import Progress
from idpose_core.view_input import ViewInput
from idpose_interfaces.action import EstimatePoses
from idpose_ros.estimate_result import view_set_estimate
from idpose_ros.node.estimator_node import NODE_NAME, SERVICE_QOS, EstimatorNode, load_configured_predictor
from idpose_ros.view_decoding import MessageView, ViewMessages, encode_view, restamped
from msg_adapters import matrix_to_pose

SERVICE_TIMEOUT = 10.0  # s to wait for a service call, a subscriber or a parameter change
CONNECT_TIMEOUT = 30.0  # s to wait for the node's action server to appear (a node may still be starting)
BUSY_RETRY = 1.0  # s between two goals while the node is busy with another estimate
INPUTS_SETTLE = 0.2  # s between publishing the views' other inputs and the goal (they go on other DDS topics)
INPUT_ATTEMPTS = 3  # goals sent before giving up on the node receiving a view's gravity
REPLAY_FRAME = "replay_camera"  # frame_id of the replayed views
VIEW_STAMP_STEP_NS = 100_000_000  # replayed views are stamped 0.1 s apart: far more than any input tolerance
# Node parameters a replay sets besides the solver's; a running node gets its own values back on close().
REPLAY_PARAMETERS = ("anchor_polar_deg", "object_distance", "anchor_frame")


class ReplayError(RuntimeError):
    """The estimator node refused, failed or did not answer; the message says which and why."""


def _wait(condition: Callable[[], bool], timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise ReplayError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(0.01)


def as_sent(view: ViewInput, stamp: TimeMsg) -> ViewMessages:
    """What the replay publishes for a view, stamped ``stamp`` in ``REPLAY_FRAME``: the messages it was read from,
    as recorded (compressed, 16UC1 depth, ...), or, for a view that has none, its lossless encoding."""
    if isinstance(view, MessageView) and view.messages is not None:
        return restamped(view.messages, stamp, REPLAY_FRAME)
    return encode_view(view, stamp, REPLAY_FRAME)


class ReplayEstimator:
    """A ``ViewSetEstimator`` that goes through the estimator node's action; call ``close()`` when done."""

    def __init__(self, values: dict[str, Any], *, model_path: str, device: str, precision: str,
                 node_name: str | None, timeout: float, preset: str, predictor: NoisePredictor | None = None):
        """``values``: the node parameters every estimate runs on (``preset`` names where they came from); the other
        options come from ``EstimatorOptions`` (``make_estimator``), whose defaults are the only ones; ``predictor``:
        the model a node started here runs, instead of the one the model parameters name."""
        self.values, self.timeout = values, timeout
        self._context = rclpy.Context()
        rclpy.init(context=self._context)
        self._executor = MultiThreadedExecutor(num_threads=4, context=self._context)
        self._estimator: EstimatorNode | None = None
        if node_name is None:
            namespace = f"/idpose_evaluate_bag_{os.getpid()}"
            # warnings and errors only, from its first line on: the terminal belongs to the progress bar
            set_logger_level(f"{namespace[1:]}.{NODE_NAME}", LoggingSeverity.WARN)
            factory = load_configured_predictor if predictor is None else lambda settings: predictor
            self._estimator = EstimatorNode(factory, context=self._context, namespace=namespace, parameter_overrides=[
                Parameter("model_path", value=model_path), Parameter("device", value=device),
                Parameter("precision", value=precision), Parameter("publish_tf", value=False)])
            self._executor.add_node(self._estimator)
            node_name = self._estimator.get_fully_qualified_name()
        self.node_name = node_name.rstrip("/")
        namespace = self.node_name.rsplit("/", 1)[0]
        self._client = rclpy.create_node("idpose_evaluate_bag", context=self._context, namespace=namespace or "/")
        self._executor.add_node(self._client)
        self._inputs = {kind: self._client.create_publisher(kind_type, f"{namespace}/{kind}", 10)
                        for kind, kind_type in (("depth", Image), ("mask", Image), ("camera_info", CameraInfo),
                                                ("camera_orientation", QuaternionStamped),
                                                ("camera_pose", PoseStamped))}
        self._action = ActionClient(self._client, EstimatePoses, f"{self.node_name}/estimate_poses",
                                    goal_service_qos_profile=SERVICE_QOS, result_service_qos_profile=SERVICE_QOS,
                                    cancel_service_qos_profile=SERVICE_QOS)
        self._parameters = AsyncParameterClient(self._client, self.node_name)
        self._spinner = threading.Thread(target=self._executor.spin, daemon=True)
        self._spinner.start()
        try:
            if not self._action.wait_for_server(timeout_sec=CONNECT_TIMEOUT):
                raise ReplayError(f"no estimator node serves {self.node_name}/estimate_poses "
                                  f"(waited {CONNECT_TIMEOUT:g} s; is --node its fully qualified name?)")
            if not self._parameters.wait_for_services(timeout_sec=CONNECT_TIMEOUT):
                raise ReplayError(f"the parameter services of {self.node_name} do not answer")
            model = {"node": self.node_name, **self._get_parameters(("model_path", "device", "precision"))}
            self.description = {"mode": "replay", "model": model, "solver_preset": preset}
            self._restore = {} if self._estimator else self._get_parameters([*self.values, *REPLAY_PARAMETERS])
        except BaseException:
            self.close()
            raise

    # ----- parameters ----------------------------------------------------------------------------------------------
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

    # ----- inputs and goals ----------------------------------------------------------------------------------------
    def _publish_inputs(self, view: ViewMessages) -> bool:
        """Publish the view's other inputs on the node's topics (the arm's camera pose where the view has one, else
        gravity as the optical frame's orientation in a z-up frame), stamped as its image; True when there were
        any."""
        stamp = view.image.header.stamp
        sent: dict[str, Any] = {"depth": view.depth, "mask": view.mask, "camera_info": view.camera_info}
        if view.camera_pose is not None:
            sent["camera_pose"] = PoseStamped(header=Header(stamp=stamp), pose=matrix_to_pose(view.camera_pose))
        elif view.gravity_up is not None:
            orientation = matrix_to_pose(np.block([[level_from_optical(view.gravity_up), np.zeros((3, 1))],
                                                   [np.zeros((1, 3)), np.ones((1, 1))]])).orientation
            sent["camera_orientation"] = QuaternionStamped(header=Header(stamp=stamp), quaternion=orientation)
        present = {kind: message for kind, message in sent.items() if message is not None}
        for kind, message in present.items():
            publisher = self._inputs[kind]
            _wait(lambda publisher=publisher: publisher.get_subscription_count() > 0, SERVICE_TIMEOUT,
                  f"the estimator to subscribe to {publisher.topic_name}")
            publisher.publish(message)
        return bool(present)

    def _run_goal(self, images: list[Image], progress: Progress | None) -> EstimatePoses.Result:
        """Send one goal and wait for its result, reporting its feedback; retried while the node is BUSY."""
        def on_feedback(message: Any) -> None:
            if progress is not None:
                progress(message.feedback.stage, round(100 * message.feedback.progress), 100)

        deadline = time.monotonic() + self.timeout
        while True:
            future = self._action.send_goal_async(EstimatePoses.Goal(images=images), feedback_callback=on_feedback)
            _wait(future.done, SERVICE_TIMEOUT, f"{self.node_name}/estimate_poses to answer the goal")
            handle = future.result()
            if not handle.accepted:
                raise ReplayError(f"{self.node_name}/estimate_poses rejected the goal")
            answer = handle.get_result_async()
            _wait(answer.done, max(deadline - time.monotonic(), 0.0), f"the result of a goal on {self.node_name}")
            result = answer.result().result
            if result.error_code != EstimatePoses.Result.BUSY or time.monotonic() + BUSY_RETRY > deadline:
                return result
            time.sleep(BUSY_RETRY)

    # ----- one view set ---------------------------------------------------------------------------------------------
    def __call__(self, views: Sequence[ViewInput], anchor_polar_deg: float, object_distance: float,
                 progress: Progress | None = None) -> ViewSetEstimate:
        self._set_parameters({**self.values, "anchor_polar_deg": float(anchor_polar_deg),
                              "object_distance": float(object_distance), "anchor_frame": ""})
        for attempt in range(1, INPUT_ATTEMPTS + 1):
            start = self._client.get_clock().now().nanoseconds
            encoded = [as_sent(view, Time(nanoseconds=start + k * VIEW_STAMP_STEP_NS).to_msg())
                       for k, view in enumerate(views)]
            if any([self._publish_inputs(view) for view in encoded]):
                time.sleep(INPUTS_SETTLE * attempt)
            result = self._run_goal([view.image for view in encoded], progress)
            if result.error_code != EstimatePoses.Result.SUCCEEDED:
                raise ReplayError(f"the estimator node's run {result.run_id} did not succeed (error code "
                                  f"{result.error_code}): {result.error_message}")
            lost = [k for k, (view, got) in enumerate(zip(encoded, result.views))
                    if view.gravity_up is not None and got.polar_source != "gravity"]
            if not lost:
                return view_set_estimate(result)
        raise ReplayError(f"{self.node_name} estimated views {lost} without the gravity published for them "
                          f"({INPUT_ATTEMPTS} attempts)")

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
