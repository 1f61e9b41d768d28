"""`ros2 run idpose_ros estimator`: buffers views of an object, estimates their camera poses, publishes them.

Glue only: messages go through msg_adapters, every number through idpose_core.pipeline. The
solver runs on a worker thread (``EstimationWorker``) while a multi-threaded executor keeps
image callbacks, services and diagnostics responsive.
"""
from __future__ import annotations

import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import CompressedImage, Image
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from idpose_core.model_loading import load_predictor
from idpose_core.pipeline import PipelineResult, ViewInput, estimate_view_poses, views_mosaic
from idpose_core.predictor import NoisePredictor
from idpose_core.solver import Progress
from idpose_ros.diagnostics import EstimatorStatus, diagnostic_array
from idpose_ros.estimation_worker import EstimationWorker, Outcome
from idpose_ros.model_holder import ModelHolder
from idpose_ros.parameters import current_values, declare_parameters, node_settings, pipeline_settings
from idpose_ros.view_buffer import CaptureRefused, View, ViewBuffer
from msg_adapters import (
    AdapterError,
    array_to_image,
    camera_markers,
    compressed_to_rgb,
    image_to_rgb,
    poses_to_pose_array,
)

NODE_NAME = "idpose_estimator"
SHUTDOWN_TIMEOUT = 1.5  # s to let a cancelled estimate stop on Ctrl-C (the node must exit within 2 s)
SPIN_PERIOD = 0.1  # s: the main thread sees Ctrl-C at least this often
RESET_TIMEOUT = 5.0  # s ~/reset waits for a cancelled estimate before clearing the buffer anyway
THROTTLE = 5.0  # s between two log lines about dropped images
MARKER_DEPTH = 0.15  # frustum depth as a share of object_distance
# Reliable and latched: a subscriber that joins late still gets the last result.
RESULT_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


class EstimatorNode(Node):
    """The `idpose_estimator` node; see the README section "The estimator node"."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        try:
            declare_parameters(self)
        except ParameterException:
            self.destroy_node()
            raise
        settings = node_settings(current_values(self))
        self._buffer = ViewBuffer(settings.max_views)
        self._worker = EstimationWorker(self.get_logger().info)
        self._model = ModelHolder(self._load_model, self._model_unavailable)
        self._status_lock = threading.Lock()
        self._state = "idle"
        self._run_id = 0  # of the running or the last estimate; ~/estimate answers it, /diagnostics carries it
        self._last_error = ""
        self._last_run_seconds: float | None = None
        self._scores: tuple[float, ...] = ()
        self._ambiguous: tuple[bool, ...] = ()
        self.add_post_set_parameters_callback(self._on_parameters_set)

        images = MutuallyExclusiveCallbackGroup()  # one image at a time keeps capture order
        services = MutuallyExclusiveCallbackGroup()  # one request at a time: no estimate/reset races
        self.create_subscription(Image, "image", self._on_image, qos_profile_sensor_data, callback_group=images)
        self.create_subscription(CompressedImage, "image/compressed", self._on_compressed, qos_profile_sensor_data,
                                 callback_group=images)
        for name, handler in (("capture", self._capture), ("estimate", self._estimate), ("cancel", self._cancel),
                              ("reset", self._reset)):
            self.create_service(Trigger, f"~/{name}", handler, callback_group=services)
        self._poses_pub = self.create_publisher(PoseArray, "~/poses", RESULT_QOS)
        self._markers_pub = self.create_publisher(MarkerArray, "~/markers", RESULT_QOS)
        self._views_pub = self.create_publisher(Image, "~/views", RESULT_QOS)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_timer(settings.diagnostics_period, self._publish_diagnostics,
                          callback_group=MutuallyExclusiveCallbackGroup())

        self.get_logger().info(f"{NODE_NAME} up: capture_mode={settings.capture_mode}, max_views={settings.max_views},"
                               f" model_path={settings.model_path or '<embedded default>'}")
        if settings.load_model_at_startup:
            self._model.preload()

    # ----- model -----------------------------------------------------------------------------------------------
    def _load_model(self) -> NoisePredictor:
        settings = node_settings(current_values(self))
        self.get_logger().info(f"loading the model ({settings.model_path or 'embedded default'}, "
                               f"device={settings.device}, precision={settings.precision})")
        started = time.monotonic()
        predictor = load_predictor(settings.model_path, device=settings.device, precision=settings.precision)
        self.get_logger().info(f"model loaded in {time.monotonic() - started:.1f} s")
        if predictor.solver_defaults:
            self.get_logger().info(f"the model recommends solver settings {dict(predictor.solver_defaults)}: they "
                                   "apply to the settings the node does not expose as parameters")
        return predictor

    def _model_unavailable(self, reason: str) -> None:
        """The one error log of a missing/broken model; ~/estimate then refuses with this reason."""
        self.get_logger().error(f"{reason} (the node stays up; ~/estimate refuses until it is restarted with a "
                                "valid model_path)")
        self._set_state("failed", reason)

    # ----- images ----------------------------------------------------------------------------------------------
    def _on_image(self, msg: Image) -> None:
        self._take(lambda: image_to_rgb(msg), msg.header, f"Image {msg.encoding}", "image")

    def _on_compressed(self, msg: CompressedImage) -> None:
        self._take(lambda: compressed_to_rgb(msg), msg.header, f"CompressedImage {msg.format}", "image/compressed")

    def _take(self, decode: Callable[[], tuple], header: Any, source: str, topic: str) -> None:
        """Decode one message; keep it as a view (auto) or remember it for ~/capture (on_request)."""
        try:
            rgb, alpha = decode()
        except AdapterError as exc:
            self.get_logger().warning(f"dropped a malformed message on {topic}: {exc}", throttle_duration_sec=THROTTLE)
            return
        except Exception as exc:  # an adapter bug must not kill the node or the views it holds
            self.get_logger().error(f"dropped a message on {topic} that failed to decode: {type(exc).__name__}: {exc}",
                                    throttle_duration_sec=THROTTLE)
            return
        view = View(ViewInput(rgb, alpha), frame_id=header.frame_id, stamp=header.stamp, source=source)
        settings = node_settings(current_values(self))
        if settings.capture_mode != "auto":
            self._buffer.observe(view)
            return
        try:
            count = self._buffer.keep_if_due(view, self._now(), settings.min_view_interval)
        except CaptureRefused as exc:
            self.get_logger().warning(f"not keeping the image: {exc}", throttle_duration_sec=THROTTLE)
            return
        if count is not None:
            self._kept(view, count, settings.views_per_estimate)

    def _kept(self, view: View, count: int, views_per_estimate: int) -> None:
        role = "anchor" if count == 1 else f"view {count}"
        height, width = view.input.rgb.shape[:2]
        self.get_logger().info(f"kept {role} ({view.source}, {width}x{height}, "
                               f"frame '{view.frame_id}'), {count} buffered")
        if views_per_estimate > 0 and count == views_per_estimate:
            _, refusal = self._start_estimate()
            if refusal:
                self.get_logger().warning(f"automatic estimate not started: {refusal}")

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    # ----- services ----------------------------------------------------------------------------------------------
    def _capture(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        try:
            view, count = self._buffer.capture_latest(self._now())
        except CaptureRefused as exc:
            response.success, response.message = False, str(exc)
            return response
        self._kept(view, count, node_settings(current_values(self)).views_per_estimate)
        response.success, response.message = True, f"captured view {count} ({view.source})"
        return response

    def _estimate(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        run_id, refusal = self._start_estimate()
        response.success = refusal is None
        response.message = refusal or f"estimating the poses of {len(self._buffer)} views (run {run_id})"
        return response

    def _cancel(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        if self._state != "estimating" or not self._worker.cancel():
            response.success, response.message = False, "no estimate is running"
            return response
        response.success = True
        response.message = f"cancelling the estimate; the {len(self._buffer)} views stay buffered"
        return response

    def _reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        cancelled = self._state == "estimating" and self._worker.cancel()
        if cancelled and not self._worker.wait(RESET_TIMEOUT):
            self.get_logger().warning(f"the cancelled estimate did not stop within {RESET_TIMEOUT} s; "
                                      "its result will be dropped")
        dropped = self._buffer.clear()
        self.get_logger().info(f"reset: dropped {dropped} views"
                               + (" after cancelling the estimate" if cancelled else ""))
        response.success = True
        response.message = f"dropped {dropped} views" + (" (cancelled the running estimate)" if cancelled else "")
        return response

    # ----- estimation ----------------------------------------------------------------------------------------------
    def _start_estimate(self) -> tuple[int | None, str | None]:
        """Start an estimate on the buffered views: (its run id, None) when started, else (None, why not)."""
        if self._model.problem:
            return None, self._model.problem
        views = self._buffer.snapshot()
        if len(views) < 2:
            return None, f"need at least 2 buffered views to estimate, have {len(views)}"
        values = current_values(self)
        settings, pipeline = node_settings(values), pipeline_settings(values)
        frame_id = settings.anchor_frame or views[0].frame_id

        def job(progress: Progress, cancel: threading.Event) -> PipelineResult:
            predictor = self._model.get()  # waits for a start-up load still running
            return estimate_view_poses(predictor, [view.input for view in views], pipeline, progress, cancel)

        def on_done(outcome: Outcome) -> None:
            self._on_estimated(outcome, views, frame_id, settings.object_distance)

        with self._status_lock:  # held so that a run that ends at once cannot be overwritten by "estimating"
            refusal = self._worker.start("estimate", job, on_done)
            if refusal is None:
                self._run_id += 1
                self._state, self._last_error, run_id = "estimating", "", self._run_id
        if refusal is not None:
            return None, refusal
        self.get_logger().info(f"estimating the poses of {len(views)} views, run {run_id} ({pipeline.solver.variant}, "
                               f"{pipeline.solver.refine_steps_per_view} refinement steps per view)")
        return run_id, None

    def _on_estimated(self, outcome: Outcome, views: list[View], frame_id: str, object_distance: float) -> None:
        if outcome.status == "cancelled":
            self.get_logger().info(f"estimate cancelled after {outcome.seconds:.1f} s; "
                                   f"the {len(self._buffer)} buffered views are kept")
            self._set_state("idle", "cancelled")
            return
        if outcome.status == "failed":
            if self._model.problem:  # already logged once by _model_unavailable
                self._set_state("failed", self._model.problem)
                return
            self.get_logger().error(f"estimate failed after {outcome.seconds:.1f} s: {outcome.error}; "
                                    f"the {len(self._buffer)} buffered views are kept")
            self._set_state("failed", outcome.error)
            return
        result: PipelineResult = outcome.value
        self._publish(result, views[0], frame_id, object_distance)
        solved = result.solver_result
        with self._status_lock:
            self._last_run_seconds = outcome.seconds
            self._scores = tuple(float(s) for s in solved.scores)
            self._ambiguous = tuple(bool(a) for a in solved.ambiguous)
        self._set_state("idle")
        self.get_logger().info(f"published {len(result.poses)} poses in frame '{frame_id}' "
                               f"after {outcome.seconds:.1f} s ({int(sum(self._ambiguous))} ambiguous)")

    def _publish(self, result: PipelineResult, anchor: View, frame_id: str, object_distance: float) -> None:
        self._poses_pub.publish(poses_to_pose_array(result.poses, frame_id, anchor.stamp))
        self._markers_pub.publish(camera_markers(result.poses, frame_id, anchor.stamp,
                                                 depth=MARKER_DEPTH * object_distance))
        mosaic = array_to_image(views_mosaic(result.preprocessed.images), "rgb8")
        mosaic.header.frame_id, mosaic.header.stamp = frame_id, anchor.stamp
        self._views_pub.publish(mosaic)

    # ----- state and diagnostics ------------------------------------------------------------------------------------
    def _set_state(self, state: str, error: str = "") -> None:
        with self._status_lock:
            self._state, self._last_error = state, error

    def status(self) -> EstimatorStatus:
        """A consistent snapshot of what /diagnostics reports."""
        progress = self._worker.progress
        with self._status_lock:
            return EstimatorStatus(
                state=self._state, run_id=self._run_id, views_buffered=len(self._buffer),
                max_views=self._buffer.max_views,
                model=self._model.describe(),
                stage=progress.stage if progress else "", progress_percent=progress.percent if progress else 0.0,
                last_error=self._last_error, last_run_seconds=self._last_run_seconds,
                scores=self._scores, ambiguous=self._ambiguous)

    def _publish_diagnostics(self) -> None:
        hardware_id = f"{self.get_fully_qualified_name()} ({node_settings(current_values(self)).device})"
        self._diagnostics_pub.publish(diagnostic_array(self.status(), hardware_id, self.get_clock().now().to_msg()))

    def _on_parameters_set(self, parameters: list[Parameter]) -> None:
        for parameter in parameters:
            if parameter.name == "max_views":
                self._buffer.max_views = parameter.value

    def stop(self, timeout: float = SHUTDOWN_TIMEOUT) -> bool:
        """Cancel a running estimate and wait up to ``timeout`` s; True when nothing is left running."""
        if self._worker.cancel():
            self.get_logger().info("shutting down: cancelling the running estimate")
        return self._worker.wait(timeout)


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt(signal.Signals(signum).name)


def run(args: list[str] | None = None) -> int:
    """Run the node until Ctrl-C (SIGINT/SIGTERM) or a ROS shutdown; returns the exit code (2: invalid parameters).

    rclpy's own signal handler would invalidate the context at once; here the signal raises
    KeyboardInterrupt in the spin loop instead, so the node still logs while it cancels and stops.
    """
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    for signum in (signal.SIGINT, signal.SIGTERM):  # also when started with SIGINT ignored (`node &` in a script)
        signal.signal(signum, _interrupt)
    try:
        node = EstimatorNode()
    except ParameterException as exc:
        rclpy.logging.get_logger(NODE_NAME).fatal(f"invalid parameters: {exc}")
        rclpy.try_shutdown()
        return 2
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    try:
        while rclpy.ok():
            executor.spin_once(timeout_sec=SPIN_PERIOD)
    except (KeyboardInterrupt, ExternalShutdownException):
        node.get_logger().info("interrupted: shutting down")
    finally:
        if not node.stop():
            node.get_logger().warning("the estimate did not stop in time; exiting anyway (it is a daemon thread)")
        executor.shutdown(timeout_sec=0.2)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def main() -> None:
    """Entry point of `ros2 run idpose_ros estimator`.

    Exits with ``os._exit`` once ROS is shut down and the output flushed: the interpreter's own
    teardown of torch, diffusers and transformers takes seconds, and Ctrl-C must end the node
    within 2 s even in the middle of an estimate.
    """
    code = run()
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":
    main()
