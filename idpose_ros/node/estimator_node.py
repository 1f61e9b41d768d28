"""The estimator lifecycle node: buffers views of an object, estimates their camera poses, publishes them.

A lifecycle node: configure loads the model, activate starts taking images and goals, deactivate
stops them (keeping the model and the views), cleanup frees the model. Estimates start from the
``EstimatePoses`` action on ``~/estimate_poses`` (``goal_server``) or from the ``~/estimate`` service; both go
through one run state (``run_state``). Images become views in ``view_intake``. Glue only: messages go through
msg_adapters, every number through idpose_core.pipeline. The solver runs on a thread of its own (``JobRunner``)
while a multi-threaded executor keeps image callbacks, services, goals and diagnostics responsive;
``process`` runs it as `ros2 run idpose_ros estimator`.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.exceptions import ParameterException
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Header
from std_srvs.srv import Trigger

from idpose_core.model_loading import load_predictor
from idpose_core.noise_predictor import NoisePredictor
from idpose_core.pipeline import PipelineResult, estimate_view_poses
from idpose_core.solver import Progress
from idpose_interfaces.action import EstimatePoses
from idpose_ros.estimate_result import result_message
from idpose_ros.node.diagnostics import EstimatorStatus, border_warning, diagnostic_array, result_inputs
from idpose_ros.node.estimate_run import EstimateRefused, EstimateRun
from idpose_ros.node.flight_recorder import FlightRecorder
from idpose_ros.node.goal_server import serve_goals
from idpose_ros.node.input_sync import InputSync
from idpose_ros.node.job_runner import JobRunner, Outcome
from idpose_ros.node.model_holder import ModelHolder, ModelUnavailable
from idpose_ros.node.parameters import (
    NodeSettings,
    current_values,
    declare_parameters,
    node_settings,
    optical_from_imu,
    pipeline_settings,
)
from idpose_ros.node.raw_image import RawImage
from idpose_ros.node.result_publisher import ResultPublisher
from idpose_ros.node.run_state import LastResult, RunPhase, RunState
from idpose_ros.node.view_buffer import CaptureRefused, View, ViewBuffer
from idpose_ros.node.view_intake import ViewIntake, view_inputs_text

NODE_NAME = "idpose_estimator"
SHUTDOWN_TIMEOUT = 1.5  # s to let a cancelled estimate stop on Ctrl-C (the node must exit within 2 s)
FALLBACK_FRAME = "idpose_anchor"  # frame of the poses when neither anchor_frame nor the anchor image names one
# Requests wait in DDS until the executor takes them; with the default depth of 10, a burst of calls
# overwrote all but the last 10 and their clients never got an answer. Every service callback answers
# at once, so a deep queue holds a burst of this many calls per service without delaying any of them.
SERVICE_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
PredictorFactory = Callable[[NodeSettings], NoisePredictor]


def load_configured_predictor(settings: NodeSettings) -> NoisePredictor:
    """The model the parameters name (``model_path``, ``device``, ``precision``): the node's default factory."""
    return load_predictor(settings.model_path, device=settings.device, precision=settings.precision)


class EstimatorNode(LifecycleNode):
    """The `idpose_estimator` lifecycle node; see docs/node.md. ``predictor_factory`` makes the model from the
    node's settings when it loads (default: ``load_configured_predictor``)."""

    def __init__(self, predictor_factory: PredictorFactory = load_configured_predictor, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        try:
            declare_parameters(self)
        except ParameterException as exc:
            self.get_logger().fatal(f"invalid parameters: {exc}")  # the node's logger: its namespace and name
            self.destroy_node()
            raise
        self._values = current_values(self)
        self._settings = node_settings(self._values)
        settings = self._settings
        self._predictor_factory = predictor_factory
        self._buffer = ViewBuffer(settings.max_views)
        self._recorder = FlightRecorder(settings.record_dir, settings.record_max_bytes, self._buffer.snapshot,
                                        self.get_logger().info, self.get_logger().error)
        self._buffer.restore(self._recorder.start(settings.resume, {"node": self.get_fully_qualified_name()}))
        self._jobs = JobRunner(self.get_logger().info)
        self._model = ModelHolder(self._load_model, self._model_unavailable)
        self._runs = RunState()
        self.add_post_set_parameters_callback(self._on_parameters_set)

        sync = InputSync(settings.gravity, optical_from_imu(settings), settings.imu_window, settings.input_tolerance)
        self._intake = ViewIntake(self, self._buffer, sync, self._recorder, lambda: self._settings,
                                  lambda: self.lifecycle_state == "active", self._after_kept)
        self._intake.subscribe()
        services = MutuallyExclusiveCallbackGroup()  # one request at a time, each answered at once
        for name, handler in (("capture", self._capture), ("estimate", self._estimate), ("cancel", self._cancel),
                              ("reset", self._reset)):
            self.create_service(Trigger, f"~/{name}", handler, qos_profile=SERVICE_QOS, callback_group=services)
        self._action = serve_goals(self, self, SERVICE_QOS)
        self._results = ResultPublisher(self, settings.publish_tf)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_timer(settings.diagnostics_period, self._publish_diagnostics,
                          callback_group=MutuallyExclusiveCallbackGroup())

        self.get_logger().info(f"{NODE_NAME} up: capture_mode={settings.capture_mode}, max_views={settings.max_views},"
                               f" model_path={settings.model_path or '<embedded default>'}")
        if settings.autostart:
            self._autostart()

    # ----- lifecycle -------------------------------------------------------------------------------------------
    @property
    def lifecycle_state(self) -> str:
        """rclpy's lifecycle state: unconfigured, inactive, active or finalized (or a transition's, while one
        runs: configuring, activating, deactivating, ...)."""
        return self._state_machine.current_state[1]

    def _autostart(self) -> None:
        """configure, then activate: what `ros2 run` gives without a lifecycle manager."""
        if self.trigger_configure() != TransitionCallbackReturn.SUCCESS:
            self.get_logger().warning("autostart: configure failed; the node stays unconfigured")
        elif self.trigger_activate() != TransitionCallbackReturn.SUCCESS:
            self.get_logger().error("autostart: activate failed; the node stays inactive")

    def _entered(self, state: str) -> TransitionCallbackReturn:
        self.get_logger().info(f"lifecycle: {state}")
        return TransitionCallbackReturn.SUCCESS

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Load the model (unless load_model_at_startup is false: then the first estimate loads it)."""
        if self._settings.load_model_at_startup:
            try:
                self._model.get()
            except ModelUnavailable:  # logged once by _model_unavailable
                return TransitionCallbackReturn.FAILURE
        return self._entered("inactive")

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        return self._entered("active")

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop taking images and goals (the node is no longer active from the transition's start); a running
        estimate is cancelled. The model and the views stay."""
        if self.cancel_run("deactivate") is not None:
            self._jobs.wait(SHUTDOWN_TIMEOUT)
        return self._entered("inactive")

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Free the model (and the CUDA cache); the buffered views stay."""
        self._jobs.wait(SHUTDOWN_TIMEOUT)
        if self._model.release():
            self.get_logger().info("cleanup: released the model")
        self._runs.set_phase(RunPhase.IDLE)
        return self._entered("unconfigured")

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """From any state: cancel a running estimate and free the model."""
        self.stop()
        self._model.release()
        return self._entered("finalized")

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.get_logger().error(f"lifecycle error in state '{state.label}': back to unconfigured")
        self._model.release()
        return self._entered("unconfigured")

    def require_active(self, what: str) -> None:
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
        settings = self._settings
        self.get_logger().info(f"loading the model ({settings.model_path or 'embedded default'}, "
                               f"device={settings.device}, precision={settings.precision})")
        started = time.monotonic()
        predictor = self._predictor_factory(settings)
        self.get_logger().info(f"model loaded in {time.monotonic() - started:.1f} s")
        if predictor.solver_defaults:
            self.get_logger().info(f"the model recommends solver settings {dict(predictor.solver_defaults)}: they "
                                   "apply to the settings the node does not expose as parameters")
        return predictor

    def _model_unavailable(self, reason: str) -> None:
        """The one error log of a missing/broken model; estimates then refuse with this reason."""
        self.get_logger().error(f"{reason} (the node stays up; estimates are refused until it is restarted with "
                                "valid model parameters: model_path, device, precision)")
        self._runs.set_phase(RunPhase.FAILED, reason)

    # ----- views -----------------------------------------------------------------------------------------------
    def prepare(self, image: RawImage) -> View:
        """An image as a view, with the inputs of its stamp (``ViewIntake.prepare``)."""
        return self._intake.prepare(image)

    def buffered_views(self) -> list[View]:
        """The views an estimate of the buffer takes, each in the recording before anyone hears of the estimate."""
        self._recorder.flush()
        views = self._buffer.snapshot()
        if len(views) < 2:
            raise EstimateRefused(EstimatePoses.Result.INVALID_GOAL,
                                  f"need at least 2 buffered views to estimate, have {len(views)}")
        return views

    def _after_kept(self, count: int) -> None:
        """Start an estimate when the buffer reaches ``views_per_estimate``."""
        if self._settings.views_per_estimate > 0 and count == self._settings.views_per_estimate:
            try:
                self.start_estimate(self.buffered_views(), self._values)
            except EstimateRefused as refusal:
                self.get_logger().warning(f"automatic estimate not started: {refusal}")

    # ----- services (each answers at once: nothing here waits for the running job) ----------------------------------
    def _capture(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        if self.lifecycle_state != "active":
            response.success, response.message = False, f"the node is {self.lifecycle_state}, not active"
            return response
        try:
            view, count = self._intake.capture()
        except CaptureRefused as exc:
            response.success, response.message = False, str(exc)
            return response
        response.success, response.message = True, f"captured view {count} ({view.source}{view_inputs_text(view)})"
        return response

    def _estimate(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        try:
            self.require_active("~/estimate")
            run = self.start_estimate(self.buffered_views(), self._values)
        except EstimateRefused as refusal:
            response.success, response.message = False, str(refusal)
            return response
        response.success = True
        response.message = f"estimating the poses of {len(run.views)} views (run {run.run_id})"
        return response

    def _cancel(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        run_id = self.cancel_run("~/cancel")
        if run_id is None:
            response.success, response.message = False, self._runs.nothing_to_cancel()
            return response
        response.success = True
        response.message = f"cancelling the estimate (run {run_id}); the {len(self._buffer)} views stay buffered"
        return response

    def _reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """Cancel a running estimate (its result is dropped whenever it stops) and drop every view, at once."""
        run_id = self.cancel_run("~/reset")
        dropped = self._buffer.clear()
        self._recorder.event("reset", dropped=dropped)
        cancelled = "" if run_id is None else f" and cancelled the estimate (run {run_id})"
        self.get_logger().info(f"reset: dropped {dropped} views{cancelled}")
        response.success = True
        response.message = f"dropped {dropped} views" + (" (cancelled the running estimate)" if cancelled else "")
        return response

    # ----- estimation ----------------------------------------------------------------------------------------------
    def parameter_values(self) -> dict[str, Any]:
        """Every parameter's current value (refreshed whenever one is set)."""
        return self._values

    def last_run_id(self) -> int:
        """The id of the running or the last estimate (0 before the first)."""
        return self._runs.run_id

    def cancel_run(self, cause: str) -> int | None:
        """Ask the running estimate to stop; its run id, or None when none is running."""
        run_id = self._runs.cancel(cause, self._jobs.cancel)
        if run_id is not None:
            self._recorder.event("cancel", run_id=run_id, by=cause)
        return run_id

    def start_estimate(self, views: list[View], values: dict[str, Any]) -> EstimateRun:
        """Start an estimate of ``views`` on these parameter values; EstimateRefused says why it did not start."""
        if self._model.problem:
            raise EstimateRefused(EstimatePoses.Result.MODEL_UNAVAILABLE, self._model.problem)
        settings, pipeline = node_settings(values), pipeline_settings(values)
        named_frame = settings.anchor_frame or views[0].frame_id
        for index, view in enumerate(views):
            if view.pending:
                self.get_logger().warning(f"view {index + 1}: no {' or '.join(sorted(view.pending))} image matched "
                                          "its stamp; it is estimated without")

        def launch(run: EstimateRun) -> str | None:
            def job(progress: Progress, cancel: threading.Event) -> PipelineResult:
                predictor = self._model.get()  # waits for a load still running

                def report(stage: str, done: int, total: int) -> None:
                    progress(stage, done, total)
                    run.on_progress(stage, done, total)
                return estimate_view_poses(predictor, [view.input for view in views], pipeline, report, cancel,
                                           samples=run.on_samples)

            return self._jobs.start("estimate", job, lambda outcome: self._on_estimated(outcome, run))

        run = self._runs.start(lambda run_id: EstimateRun(run_id, views, named_frame or FALLBACK_FRAME,
                                                          values=values), launch)
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
            cause = self._runs.cancelled_by
            kept = {"~/reset": "its views were dropped"}.get(cause, f"the {len(self._buffer)} buffered views stay "
                                                                 "for a retry")
            message = f"cancelled by {cause}; {kept}"
            self.get_logger().info(f"estimate (run {run_id}) stopped {outcome.seconds:.1f} s after it started, "
                                   f"{message}")
            self._runs.finish(run, RunPhase.IDLE, codes(error_code=codes.CANCELED, error_message=message,
                                                        run_id=run_id))
            return
        if outcome.status == "failed":
            if self._model.problem:  # already logged once by _model_unavailable
                self._runs.finish(run, RunPhase.FAILED, codes(error_code=codes.MODEL_UNAVAILABLE,
                                                              error_message=self._model.problem, run_id=run_id))
                return
            self.get_logger().error(f"estimate (run {run_id}) failed after {outcome.seconds:.1f} s: {outcome.error}; "
                                    f"the {len(self._buffer)} buffered views are kept")
            self._runs.finish(run, RunPhase.FAILED, codes(error_code=codes.FAILED, error_message=outcome.error,
                                                          run_id=run_id))
            return
        result: PipelineResult = outcome.value
        headers = [Header(frame_id=view.frame_id, stamp=view.stamp) for view in run.views]
        message = result_message(result, headers, run.frame_id, run_id, outcome.seconds)
        self._recorder.result(message, run.values, run.views)  # recorded before anyone can see it
        self._results.publish(result, message, self._settings.tf_prefix)
        solved = result.solver_result
        last = LastResult(outcome.seconds, tuple(float(s) for s in solved.scores),
                          tuple(bool(a) for a in solved.ambiguous), result_inputs(result))
        self._runs.finish(run, RunPhase.IDLE, message, last)
        if warning := border_warning(result):
            self.get_logger().warning(warning)
        if solved.note:
            self.get_logger().warning(f"run {run_id}: {solved.note}")
        self.get_logger().info(f"published {len(result.poses)} poses in frame '{run.frame_id}' "
                               f"after {outcome.seconds:.1f} s ({int(sum(last.ambiguous))} ambiguous)")

    # ----- status and parameters ------------------------------------------------------------------------------------
    def status(self) -> EstimatorStatus:
        """A consistent snapshot of what /diagnostics reports."""
        progress = self._jobs.progress
        run = self._runs.snapshot()
        return EstimatorStatus(
            state=run.phase, run_id=run.run_id, views_buffered=len(self._buffer), max_views=self._buffer.max_views,
            model=self._model.describe(), lifecycle=self.lifecycle_state,
            images_received=self._intake.images_received,
            stage=progress.stage if progress else "", progress_percent=progress.percent if progress else 0.0,
            last_error=run.last_error, last_run_seconds=run.last.seconds, scores=run.last.scores,
            ambiguous=run.last.ambiguous, inputs=run.last.inputs, recording=self._recorder.status())

    def _publish_diagnostics(self) -> None:
        self._recorder.flush()  # the views it counts are in the recording
        hardware_id = f"{self.get_fully_qualified_name()} ({self._settings.device})"
        self._diagnostics_pub.publish(diagnostic_array(self.status(), hardware_id, self.get_clock().now().to_msg()))

    def _on_parameters_set(self, parameters: list[Parameter]) -> None:
        """Refresh the cached values and settings; a new ``max_views`` applies to the buffer at once."""
        self._values = current_values(self)
        self._settings = node_settings(self._values)
        if any(parameter.name == "max_views" for parameter in parameters):
            self._buffer.max_views = self._settings.max_views

    def stop(self, timeout: float = SHUTDOWN_TIMEOUT) -> bool:
        """Cancel a running estimate and wait up to ``timeout`` s; True when nothing is left running."""
        if self.cancel_run("shutdown") is not None:
            self.get_logger().info("shutting down: cancelling the running estimate")
        stopped = self._jobs.wait(timeout)
        self._recorder.close()
        return stopped
