"""`ros2 run idpose_ros estimator`: buffers views of an object, estimates their camera poses, publishes them.

A lifecycle node: configure loads the model, activate starts taking images and goals, deactivate
stops them (keeping the model and the views), cleanup frees the model. Estimates start from the
``EstimatePoses`` action on ``~/estimate_poses`` or from the ``~/estimate`` service; both go through
one run state. Glue only: messages go through msg_adapters, every number through idpose_core.pipeline.
The solver runs on a thread of its own (``JobRunner``) while a multi-threaded executor keeps
image callbacks, services, goals and diagnostics responsive.
"""
from __future__ import annotations

import logging
import os
import signal
import sys
import threading
import time
from dataclasses import replace
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped, QuaternionStamped
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, Imu, RegionOfInterest
from std_msgs.msg import Header
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from idpose_core.model_loading import load_predictor
from idpose_core.noise_predictor import NoisePredictor
from idpose_core.pipeline import PipelineResult, estimate_view_poses, views_mosaic
from idpose_core.preprocessing import PreprocessingError, precheck_view
from idpose_core.solver import Progress, SolverConfig
from idpose_interfaces.action import EstimatePoses
from idpose_ros.estimate_result import result_message
from idpose_ros.node.diagnostics import RUNNING_STATES, EstimatorStatus, border_warning, diagnostic_array, result_inputs
from idpose_ros.node.estimate_run import EstimateRefused, EstimateRun, refusal_result
from idpose_ros.node.flight_recorder import FlightRecorder, subscribe_tf
from idpose_ros.node.input_sync import IMAGE_INPUTS, InputSync
from idpose_ros.node.job_runner import JobRunner, Outcome
from idpose_ros.node.model_holder import ModelHolder, ModelUnavailable
from idpose_ros.node.parameters import (
    SOLVER_PARAMETERS,
    NodeSettings,
    current_values,
    declare_parameters,
    node_settings,
    optical_from_imu,
    pipeline_settings,
)
from idpose_ros.node.raw_image import RawImage
from idpose_ros.node.tf_broadcast import PoseBroadcaster
from idpose_ros.node.view_buffer import CaptureRefused, ImageRefused, View, ViewBuffer
from idpose_ros.view_decoding import ViewMessages, with_inputs
from msg_adapters import (
    AdapterError,
    ImageTooLarge,
    array_to_image,
    camera_markers,
    stamp_nanoseconds,
)

NODE_NAME = "idpose_estimator"
SHUTDOWN_TIMEOUT = 1.5  # s to let a cancelled estimate stop on Ctrl-C (the node must exit within 2 s)
SPIN_PERIOD = 0.1  # s: the main thread sees Ctrl-C at least this often
THROTTLE = 5.0  # s between two log lines about refused images
FEEDBACK_PERIOD = 0.5  # s between two feedback messages of a goal
CANCEL_POLL = 0.05  # s between two looks of a goal at its cancel request
MARKER_DEPTH = 0.15  # frustum depth as a share of object_distance
FALLBACK_FRAME = "idpose_anchor"  # frame of the poses when neither anchor_frame nor the anchor image names one
# Reliable and latched: a subscriber that joins late still gets the last result.
RESULT_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
# Requests wait in DDS until the executor takes them; with the default depth of 10, a burst of calls
# overwrote all but the last 10 and their clients never got an answer. Every service callback answers
# at once, so a deep queue holds a burst of this many calls per service without delaying any of them.
SERVICE_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
# An IMU publishes hundreds of readings a second: a deep best-effort queue keeps them while a callback runs.
IMU_QOS = QoSProfile(depth=200, reliability=ReliabilityPolicy.BEST_EFFORT)


def view_inputs_text(view: View) -> str:
    """", with depth, gravity" etc. for the inputs a kept view has (and ", depth pending" for those still to come)."""
    have = [name for name, value in (("mask", view.input.mask), ("depth", view.input.depth),
                                     ("intrinsics", view.input.intrinsics), ("gravity", view.input.gravity_up),
                                     ("roi", view.input.roi)) if value is not None]
    pending = [f"{kind} pending" for kind in sorted(view.pending)]
    return "".join(f", {item}" for item in (["with " + ", ".join(have)] if have else []) + pending)


class EstimatorNode(LifecycleNode):
    """The `idpose_estimator` lifecycle node; see docs/node.md."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        try:
            declare_parameters(self)
        except ParameterException as exc:
            self.get_logger().fatal(f"invalid parameters: {exc}")  # the node's logger: its namespace and name
            self.destroy_node()
            raise
        settings = node_settings(current_values(self))
        self._buffer = ViewBuffer(settings.max_views)
        self._sync = InputSync(settings.gravity, optical_from_imu(settings), settings.imu_window,
                               settings.input_tolerance)
        self._roi: tuple[int, int, int, int] | None = None  # the latest region of interest, for views kept later
        self._recorder = FlightRecorder(settings.record_dir, settings.record_max_bytes, self._buffer.snapshot,
                                        self.get_logger().info, self.get_logger().error)
        self._buffer.restore(self._recorder.start(settings.resume, {"node": self.get_fully_qualified_name()}))
        self._jobs = JobRunner(self.get_logger().info)
        self._model = ModelHolder(self._load_model, self._model_unavailable)
        self._status_lock = threading.Lock()
        self._lifecycle = "unconfigured"
        self._state = "idle"
        self._run_id = 0  # of the running or the last estimate; every answer and result carries it
        self._run: EstimateRun | None = None  # the running or the last estimate
        self._cancelled_by = ""  # what cancelled the current run: "~/cancel", "~/reset", an action cancel, ...
        self._images_received = 0  # counted by the image callbacks only (one callback group)
        self._last_error = ""
        self._last_run_seconds: float | None = None
        self._scores: tuple[float, ...] = ()
        self._ambiguous: tuple[bool, ...] = ()
        self._inputs: dict[str, str] = {}
        self.add_post_set_parameters_callback(self._on_parameters_set)

        images = MutuallyExclusiveCallbackGroup()  # one image at a time keeps capture order
        services = MutuallyExclusiveCallbackGroup()  # one request at a time, each answered at once
        self.create_subscription(Image, "image", self._on_image, qos_profile_sensor_data, callback_group=images)
        self.create_subscription(CompressedImage, "image/compressed", self._on_compressed, qos_profile_sensor_data,
                                 callback_group=images)
        inputs = MutuallyExclusiveCallbackGroup()  # depth, masks, intrinsics, gravity, region of interest
        for kind in IMAGE_INPUTS:
            self.create_subscription(Image, kind, lambda msg, kind=kind: self._on_image_input(kind, msg),
                                     qos_profile_sensor_data, callback_group=inputs)
        self.create_subscription(CameraInfo, "camera_info", self._sync.add_camera_info, qos_profile_sensor_data,
                                 callback_group=inputs)
        if settings.gravity != "off":
            self.create_subscription(Imu, "imu", self._on_imu, IMU_QOS, callback_group=inputs)
            for kind, topic in ((QuaternionStamped, "camera_orientation"), (PoseStamped, "camera_pose")):
                self.create_subscription(kind, topic, self._on_orientation, qos_profile_sensor_data,
                                         callback_group=inputs)
        self.create_subscription(RegionOfInterest, "roi", self._on_roi, 10, callback_group=inputs)
        if self._recorder.on:
            self.get_logger().info(subscribe_tf(self, self._recorder, inputs))
        for name, handler in (("capture", self._capture), ("estimate", self._estimate), ("cancel", self._cancel),
                              ("reset", self._reset)):
            self.create_service(Trigger, f"~/{name}", handler, qos_profile=SERVICE_QOS, callback_group=services)
        # Goals wait on their run in the executor's threads; they must not block each other or the services.
        self._action = ActionServer(self, EstimatePoses, "~/estimate_poses", self._execute_goal,
                                    goal_callback=lambda goal: GoalResponse.ACCEPT,
                                    cancel_callback=lambda goal_handle: CancelResponse.ACCEPT,
                                    callback_group=ReentrantCallbackGroup(), goal_service_qos_profile=SERVICE_QOS,
                                    result_service_qos_profile=SERVICE_QOS, cancel_service_qos_profile=SERVICE_QOS)
        self._poses_pub = self.create_publisher(PoseArray, "~/poses", RESULT_QOS)
        self._markers_pub = self.create_publisher(MarkerArray, "~/markers", RESULT_QOS)
        self._views_pub = self.create_publisher(Image, "~/views", RESULT_QOS)
        self._tf = PoseBroadcaster(self, self.get_logger().warning) if settings.publish_tf else None
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_timer(settings.diagnostics_period, self._publish_diagnostics,
                          callback_group=MutuallyExclusiveCallbackGroup())

        self.get_logger().info(f"{NODE_NAME} up: capture_mode={settings.capture_mode}, max_views={settings.max_views},"
                               f" model_path={settings.model_path or '<embedded default>'}")
        if settings.autostart:
            self._autostart()

    # ----- lifecycle -------------------------------------------------------------------------------------------
    def _autostart(self) -> None:
        """configure, then activate: what `ros2 run` gives without a lifecycle manager."""
        if self.trigger_configure() != TransitionCallbackReturn.SUCCESS:
            self.get_logger().warning("autostart: configure failed; the node stays unconfigured")
        elif self.trigger_activate() != TransitionCallbackReturn.SUCCESS:
            self.get_logger().error("autostart: activate failed; the node stays inactive")

    def _entered(self, state: str) -> TransitionCallbackReturn:
        with self._status_lock:
            self._lifecycle = state
        self.get_logger().info(f"lifecycle: {state}")
        return TransitionCallbackReturn.SUCCESS

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Load the model (unless load_model_at_startup is false: then the first estimate loads it)."""
        if node_settings(current_values(self)).load_model_at_startup:
            try:
                self._model.get()
            except ModelUnavailable:  # logged once by _model_unavailable
                return TransitionCallbackReturn.FAILURE
        return self._entered("inactive")

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        return self._entered("active")

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop taking images and goals; a running estimate is cancelled. The model and the views stay."""
        with self._status_lock:
            self._lifecycle = "inactive"
        if self._cancel_run("deactivate") is not None:
            self._jobs.wait(SHUTDOWN_TIMEOUT)
        return self._entered("inactive")

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Free the model (and the CUDA cache); the buffered views stay."""
        self._jobs.wait(SHUTDOWN_TIMEOUT)
        if self._model.release():
            self.get_logger().info("cleanup: released the model")
        self._set_state("idle")
        return self._entered("unconfigured")

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """From any state: cancel a running estimate and free the model."""
        with self._status_lock:
            self._lifecycle = "finalized"
        self.stop()
        self._model.release()
        return self._entered("finalized")

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.get_logger().error(f"lifecycle error in state '{state.label}': back to unconfigured")
        self._model.release()
        return self._entered("unconfigured")

    @property
    def lifecycle_state(self) -> str:
        """unconfigured, inactive, active or finalized."""
        with self._status_lock:
            return self._lifecycle

    def _require_active(self, what: str) -> None:
        """EstimateRefused (NOT_ACTIVE, or MODEL_UNAVAILABLE after a failed load) unless the node is active."""
        state = self.lifecycle_state
        if state == "active":
            return
        if self._model.problem:
            raise EstimateRefused(EstimatePoses.Result.MODEL_UNAVAILABLE, self._model.problem)
        raise EstimateRefused(EstimatePoses.Result.NOT_ACTIVE,
                              f"the node is {state}, not active: {what} refused (activate it through its "
                              "lifecycle, or start it with autostart true)")

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
        """The one error log of a missing/broken model; estimates then refuse with this reason."""
        self.get_logger().error(f"{reason} (the node stays up; estimates are refused until it is restarted with "
                                "valid model parameters: model_path, device, precision)")
        self._set_state("failed", reason)

    # ----- images ----------------------------------------------------------------------------------------------
    def _on_image(self, msg: Image) -> None:
        self._on_message(RawImage(msg, "image"))

    def _on_compressed(self, msg: CompressedImage) -> None:
        self._on_message(RawImage(msg, "image/compressed"))

    def _on_message(self, image: RawImage) -> None:
        """Remember the image undecoded; in auto mode, keep it as a view when one is due. Ignored unless active."""
        if self.lifecycle_state != "active":
            return
        self._images_received += 1
        self._buffer.observe(image)
        settings = node_settings(current_values(self))
        if settings.capture_mode != "auto" or not self._buffer.due(self._now(), settings.min_view_interval):
            return
        try:
            view, count = self._buffer.keep_latest(self._prepare, self._now())
        except ImageRefused as exc:
            self.get_logger().warning(f"refused {exc}", throttle_duration_sec=THROTTLE)
            return
        except CaptureRefused as exc:
            self.get_logger().warning(f"not keeping the image: {exc}", throttle_duration_sec=THROTTLE)
            return
        self._kept(view, count, settings)
    def _prepare(self, image: RawImage) -> View:
        """Decode ``image`` (its size checked first) with the other inputs of its stamp and check it can be a view;
        ``ImageRefused`` says why not. Whatever goes wrong, the node and the views it holds stay.
        """
        name = f"{image.source} on {image.topic}"
        try:
            pixels = image.decode(node_settings(current_values(self)).max_image_pixels)
            height, width = pixels.rgb.shape[:2]
            now = self.get_clock().now().nanoseconds
            matched = self._sync.match(stamp_nanoseconds(image.stamp), (width, height), now)
            if matched.gravity_problem:
                if self._sync.gravity == "required":
                    raise ImageRefused(f"{name}: no gravity reading for it ({matched.gravity_problem}; gravity: "
                                       "required)")
                self.get_logger().warning(f"{name}: kept without gravity ({matched.gravity_problem})",
                                          throttle_duration_sec=THROTTLE)
            roi = self._roi
            pixels = with_inputs(pixels, matched.depth, matched.mask, matched.camera_info, matched.gravity_up, roi)
            precheck_view(pixels, name)
            received = (ViewMessages(image.message, matched.depth, matched.mask, matched.camera_info,
                                     matched.gravity_up, roi, matched.gravity_source) if self._recorder.on else None)
        except ImageRefused:
            raise
        except ImageTooLarge as exc:
            raise ImageRefused(f"{name}: {exc} (max_image_pixels)") from exc
        except AdapterError as exc:
            raise ImageRefused(f"{name}: {exc}") from exc
        except PreprocessingError as exc:  # it names the image itself
            raise ImageRefused(str(exc)) from exc
        except Exception as exc:  # an adapter bug must not kill the node or the views it holds
            raise ImageRefused(f"{name}: it failed to decode: {type(exc).__name__}: {exc}") from exc
        return View(pixels, frame_id=image.frame_id, stamp=image.stamp, source=image.source, pending=matched.pending,
                    received=received)

    # ----- other inputs ----------------------------------------------------------------------------------------
    def _on_image_input(self, kind: str, msg: Image) -> None:
        """A depth or mask image: kept for views to come, and given to kept views still waiting for it."""
        self._sync.add_image(kind, msg, self.get_clock().now().nanoseconds)

        def fill(view: View) -> View | None:
            if not self._sync.fits(kind, msg, stamp_nanoseconds(view.stamp)):
                return None
            try:
                done = replace(view, input=with_inputs(view.input, **{kind: msg}), pending=view.pending - {kind},
                               received=view.received and replace(view.received, **{kind: msg}))
                self._recorder.view_input(view, kind, msg)
                return done
            except AdapterError as exc:
                taken = stamp_nanoseconds(view.stamp) * 1e-9
                self.get_logger().warning(f"the {kind} image for a view taken at {taken:.3f} s is not used: {exc}",
                                          throttle_duration_sec=THROTTLE)
                return replace(view, pending=view.pending - {kind})

        self._buffer.complete(kind, fill)

    def _on_imu(self, msg: Imu) -> None:
        try:
            self._sync.add_imu(msg, self.get_clock().now().nanoseconds)
        except AdapterError as exc:
            self.get_logger().warning(f"dropped an imu message: {exc}", throttle_duration_sec=THROTTLE)

    def _on_orientation(self, msg: QuaternionStamped | PoseStamped) -> None:
        try:
            self._sync.add_orientation(msg, self.get_clock().now().nanoseconds)
        except AdapterError as exc:
            self.get_logger().warning(f"dropped a camera orientation: {exc}", throttle_duration_sec=THROTTLE)

    def _on_roi(self, msg: RegionOfInterest) -> None:
        """Views kept from now on look for their object here (an empty region clears it)."""
        self._roi = (msg.x_offset, msg.y_offset, msg.width, msg.height) if msg.width and msg.height else None

    def _kept(self, view: View, count: int, settings: NodeSettings) -> None:
        self._recorder.view_kept(count, view)
        role = "anchor" if count == 1 else f"view {count}"
        height, width = view.input.rgb.shape[:2]
        self.get_logger().info(f"kept {role} ({view.source}, {width}x{height}, "
                               f"frame '{view.frame_id}'), {count} buffered")
        anchor = self._buffer.anchor()
        if count > 1 and anchor is not None and view.frame_id != anchor.frame_id:
            self.get_logger().warning(
                f"view {count} is in frame '{view.frame_id}' but the anchor in '{anchor.frame_id}': images from "
                "different cameras or publishers are mixed in one view set (call ~/reset between objects)")
        if settings.views_per_estimate > 0 and count == settings.views_per_estimate:
            try:
                self._start_estimate(self._buffered_views(), current_values(self))
            except EstimateRefused as refusal:
                self.get_logger().warning(f"automatic estimate not started: {refusal}")


    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    # ----- services (each answers at once: nothing here waits for the running job) ----------------------------------
    def _capture(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        if self.lifecycle_state != "active":
            response.success, response.message = False, f"the node is {self.lifecycle_state}, not active"
            return response
        try:
            view, count = self._buffer.keep_latest(self._prepare, self._now())
        except ImageRefused as exc:
            self.get_logger().warning(f"~/capture refused {exc}")
            response.success, response.message = False, str(exc)
            return response
        except CaptureRefused as exc:
            response.success, response.message = False, str(exc)
            return response
        self._kept(view, count, node_settings(current_values(self)))
        self._recorder.flush()  # a view the answer names is in the recording
        response.success, response.message = True, f"captured view {count} ({view.source}{view_inputs_text(view)})"
        return response

    def _estimate(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        try:
            self._require_active("~/estimate")
            run = self._start_estimate(self._buffered_views(), current_values(self))
        except EstimateRefused as refusal:
            response.success, response.message = False, str(refusal)
            return response
        response.success = True
        response.message = f"estimating the poses of {len(run.views)} views (run {run.run_id})"
        return response

    def _cancel(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        run_id = self._cancel_run("~/cancel")
        if run_id is None:
            response.success, response.message = False, self._nothing_to_cancel()
            return response
        response.success = True
        response.message = f"cancelling the estimate (run {run_id}); the {len(self._buffer)} views stay buffered"
        return response

    def _reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """Cancel a running estimate (its result is dropped whenever it stops) and drop every view, at once."""
        run_id = self._cancel_run("~/reset")
        dropped = self._buffer.clear()
        self._recorder.event("reset", dropped=dropped)
        cancelled = "" if run_id is None else f" and cancelled the estimate (run {run_id})"
        self.get_logger().info(f"reset: dropped {dropped} views{cancelled}")
        response.success = True
        response.message = f"dropped {dropped} views" + (" (cancelled the running estimate)" if cancelled else "")
        return response

    def _cancel_run(self, cause: str) -> int | None:
        """Ask the running estimate to stop; its run id, or None when none is running."""
        with self._status_lock:
            if self._state != "estimating" or not self._jobs.cancel():
                return None
            self._state, self._cancelled_by = "cancelling", cause
            run_id = self._run_id
        self._recorder.event("cancel", run_id=run_id, by=cause)
        return run_id

    def _nothing_to_cancel(self) -> str:
        with self._status_lock:
            if self._state == "cancelling":
                return f"the estimate (run {self._run_id}) is already stopping"
            return "no estimate is running"

    # ----- the EstimatePoses action ---------------------------------------------------------------------------------
    def _execute_goal(self, goal_handle: ServerGoalHandle) -> EstimatePoses.Result:
        """Run the goal's estimate (or refuse it at once with the reason), with feedback every FEEDBACK_PERIOD s;
        a cancel request stops it within a model module (the buffered views stay)."""
        try:
            self._require_active("the EstimatePoses goal")
            run = self._start_estimate(self._goal_views(goal_handle.request), self._goal_values(goal_handle.request))
        except EstimateRefused as refusal:
            goal_handle.abort()
            return refusal_result(refusal, self._run_id)
        cancel_asked = False
        goal_handle.publish_feedback(run.feedback())
        next_feedback = time.monotonic() + FEEDBACK_PERIOD
        while not run.finished.wait(CANCEL_POLL):
            if goal_handle.is_cancel_requested and not cancel_asked:
                cancel_asked = self._cancel_run("an EstimatePoses cancel") is not None
            if time.monotonic() >= next_feedback:
                goal_handle.publish_feedback(run.feedback())
                next_feedback = time.monotonic() + FEEDBACK_PERIOD
        result = run.result
        if result.error_code == EstimatePoses.Result.SUCCEEDED:
            goal_handle.succeed()
        elif result.error_code == EstimatePoses.Result.CANCELED and goal_handle.is_cancel_requested:
            goal_handle.canceled()
        else:
            goal_handle.abort()
        return result

    def _goal_views(self, goal: EstimatePoses.Goal) -> list[View]:
        """The goal's images as views (matched with the inputs on the node's topics by stamp, like captured
        images), or the buffered views when it has none; EstimateRefused (INVALID_GOAL) names a bad image."""
        if not goal.images:
            return self._buffered_views()
        if len(goal.images) < 2:
            raise EstimateRefused(EstimatePoses.Result.INVALID_GOAL,
                                  f"a goal needs at least 2 images (the anchor first), got {len(goal.images)}")
        views = []
        for index, image in enumerate(goal.images):
            try:
                views.append(self._prepare(RawImage(image, f"goal image {index}")))
            except ImageRefused as exc:
                raise EstimateRefused(EstimatePoses.Result.INVALID_GOAL, str(exc)) from exc
        return views

    def _goal_values(self, goal: EstimatePoses.Goal) -> dict[str, Any]:
        """The node's parameter values, with the goal's solver preset (if named) in place of its solver ones."""
        values = current_values(self)
        if not goal.preset:
            return values
        try:
            config = SolverConfig.preset(goal.preset)
        except ValueError as exc:
            raise EstimateRefused(EstimatePoses.Result.INVALID_GOAL, f"preset: {exc}") from exc
        return {**values, "preset": goal.preset, **{name: getattr(config, name) for name in SOLVER_PARAMETERS}}

    # ----- estimation ----------------------------------------------------------------------------------------------
    def _buffered_views(self) -> list[View]:
        """The views an estimate of the buffer takes, each in the recording before anyone hears of the estimate."""
        self._recorder.flush()
        views = self._buffer.snapshot()
        if len(views) < 2:
            raise EstimateRefused(EstimatePoses.Result.INVALID_GOAL,
                                  f"need at least 2 buffered views to estimate, have {len(views)}")
        return views

    def _start_estimate(self, views: list[View], values: dict[str, Any]) -> EstimateRun:
        """Start an estimate of ``views`` on these parameter values; EstimateRefused says why it did not start."""
        if self._model.problem:
            raise EstimateRefused(EstimatePoses.Result.MODEL_UNAVAILABLE, self._model.problem)
        settings, pipeline = node_settings(values), pipeline_settings(values)
        named_frame = settings.anchor_frame or views[0].frame_id
        frame_id = named_frame or FALLBACK_FRAME
        for index, view in enumerate(views):
            if view.pending:
                self.get_logger().warning(f"view {index + 1}: no {' or '.join(sorted(view.pending))} image matched "
                                          "its stamp; it is estimated without")

        with self._status_lock:  # held so that a run that ends at once cannot be overwritten by "estimating"
            if self._state in RUNNING_STATES:
                verb = "running" if self._state == "estimating" else "stopping after a cancel"
                raise EstimateRefused(EstimatePoses.Result.BUSY, f"busy: the estimate (run {self._run_id}) is {verb}")
            run = EstimateRun(self._run_id + 1, views, frame_id, values=values)

            def job(progress: Progress, cancel: threading.Event) -> PipelineResult:
                predictor = self._model.get()  # waits for a load still running
                def report(stage: str, done: int, total: int) -> None:
                    progress(stage, done, total)
                    run.on_progress(stage, done, total)
                return estimate_view_poses(predictor, [view.input for view in views], pipeline, report, cancel,
                                           samples=run.on_samples)

            refusal = self._jobs.start("estimate", job, lambda outcome: self._on_estimated(outcome, run))
            if refusal is None:
                self._run_id, self._run, self._state, self._last_error = run.run_id, run, "estimating", ""
        if refusal is not None:
            raise EstimateRefused(EstimatePoses.Result.BUSY, refusal)
        self.get_logger().info(f"estimating the poses of {len(views)} views, run {run.run_id} "
                               f"({pipeline.solver.variant}, {pipeline.solver.refine_steps_per_view} refinement steps "
                               "per view)")
        if not named_frame:
            self.get_logger().warning(f"the anchor image has no header.frame_id and anchor_frame is not set: "
                                      f"publishing the poses in frame '{FALLBACK_FRAME}'")
        return run

    def _on_estimated(self, outcome: Outcome, run: EstimateRun) -> None:
        """Publish a result (poses, markers, views, TF), or log why there is none; then end the run's state."""
        run_id, codes = run.run_id, EstimatePoses.Result
        if outcome.status == "cancelled":
            cause = self._cancelled_by
            kept = {"~/reset": "its views were dropped"}.get(cause, f"the {len(self._buffer)} buffered views stay "
                                                                 "for a retry")
            message = f"cancelled by {cause}; {kept}"
            self.get_logger().info(f"estimate (run {run_id}) stopped {outcome.seconds:.1f} s after it started, "
                                   f"{message}")
            self._finish(run, "idle", codes(error_code=codes.CANCELED, error_message=message, run_id=run_id))
            return
        if outcome.status == "failed":
            if self._model.problem:  # already logged once by _model_unavailable
                self._finish(run, "failed", codes(error_code=codes.MODEL_UNAVAILABLE,
                                                  error_message=self._model.problem, run_id=run_id))
                return
            self.get_logger().error(f"estimate (run {run_id}) failed after {outcome.seconds:.1f} s: {outcome.error}; "
                                    f"the {len(self._buffer)} buffered views are kept")
            self._finish(run, "failed", codes(error_code=codes.FAILED, error_message=outcome.error, run_id=run_id))
            return
        result: PipelineResult = outcome.value
        headers = [Header(frame_id=view.frame_id, stamp=view.stamp) for view in run.views]
        message = result_message(result, headers, run.frame_id, run_id, outcome.seconds)
        self._recorder.result(message, run.values, run.views)  # recorded before anyone can see it
        self._publish(result, message)
        solved = result.solver_result
        with self._status_lock:
            self._last_run_seconds = outcome.seconds
            self._scores = tuple(float(s) for s in solved.scores)
            self._ambiguous = tuple(bool(a) for a in solved.ambiguous)
            self._inputs = result_inputs(result)
        self._finish(run, "idle", message)
        if warning := border_warning(result):
            self.get_logger().warning(warning)
        self.get_logger().info(f"published {len(result.poses)} poses in frame '{run.frame_id}' "
                               f"after {outcome.seconds:.1f} s ({int(sum(self._ambiguous))} ambiguous)")

    def _publish(self, result: PipelineResult, message: EstimatePoses.Result) -> None:
        """Poses (the result's own PoseArray), markers, the views the model saw and TF; the markers are sized by
        the distance the poses use (measured from depth when the anchor had it)."""
        poses = message.poses
        self._poses_pub.publish(poses)
        self._markers_pub.publish(camera_markers(result.poses, poses.header.frame_id, poses.header.stamp,
                                                 depth=MARKER_DEPTH * result.object_distance))
        mosaic = array_to_image(views_mosaic(result.preprocessed.images), "rgb8")
        mosaic.header = poses.header
        self._views_pub.publish(mosaic)
        if self._tf is not None:
            self._tf.broadcast(poses, node_settings(current_values(self)).tf_prefix)

    # ----- state and diagnostics ------------------------------------------------------------------------------------
    def _set_state(self, state: str, error: str = "") -> None:
        with self._status_lock:
            self._state, self._last_error = state, error

    def _finish(self, run: EstimateRun, state: str, result: EstimatePoses.Result) -> None:
        """End ``run`` with ``result``; the node's state follows unless a later run has started meanwhile."""
        with self._status_lock:
            if run.run_id == self._run_id:
                self._state = state
                self._last_error = {EstimatePoses.Result.SUCCEEDED: "", EstimatePoses.Result.CANCELED: "cancelled"}.get(
                    result.error_code, result.error_message)
        run.finish(result)

    def status(self) -> EstimatorStatus:
        """A consistent snapshot of what /diagnostics reports."""
        progress = self._jobs.progress
        with self._status_lock:
            return EstimatorStatus(
                state=self._state, run_id=self._run_id, views_buffered=len(self._buffer),
                max_views=self._buffer.max_views, model=self._model.describe(), lifecycle=self._lifecycle,
                images_received=self._images_received,
                stage=progress.stage if progress else "", progress_percent=progress.percent if progress else 0.0,
                last_error=self._last_error, last_run_seconds=self._last_run_seconds,
                scores=self._scores, ambiguous=self._ambiguous, inputs=self._inputs,
                recording=self._recorder.status())

    def _publish_diagnostics(self) -> None:
        self._recorder.flush()  # the views it counts are in the recording
        hardware_id = f"{self.get_fully_qualified_name()} ({node_settings(current_values(self)).device})"
        self._diagnostics_pub.publish(diagnostic_array(self.status(), hardware_id, self.get_clock().now().to_msg()))

    def _on_parameters_set(self, parameters: list[Parameter]) -> None:
        for parameter in parameters:
            if parameter.name == "max_views":
                self._buffer.max_views = parameter.value

    def stop(self, timeout: float = SHUTDOWN_TIMEOUT) -> bool:
        """Cancel a running estimate and wait up to ``timeout`` s; True when nothing is left running."""
        if self._cancel_run("shutdown") is not None:
            self.get_logger().info("shutting down: cancelling the running estimate")
        stopped = self._jobs.wait(timeout)
        self._recorder.close()
        return stopped


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
        node = EstimatorNode()  # with autostart, the model loads here
    except ParameterException:  # logged by the node, under its full name
        rclpy.try_shutdown()
        return 2
    except KeyboardInterrupt:  # while the model loaded
        rclpy.try_shutdown()
        return 0
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
