"""The estimator lifecycle node: buffers views of an object, estimates their camera poses, publishes them.

A lifecycle node: configure loads the model, activate starts taking images and goals, deactivate
stops them (keeping the model and the views), cleanup frees the model. Images become views in ``view_intake``;
estimates start, run and publish in ``estimation``, whether the ``EstimatePoses`` action on ``~/estimate_poses``
(``goal_server``), the ``~/estimate`` service or a full buffer asks. The node wires these rooms, keeps their
``NodeState`` current and answers the services. Glue only: messages go through msg_adapters, every number through
idpose_core.pipeline. The solver runs on a thread of its own while a multi-threaded executor keeps image
callbacks, services, goals and diagnostics responsive; ``process`` runs it as `ros2 run idpose_ros estimator`.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.exceptions import ParameterException
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_srvs.srv import Trigger

from idpose_core.model_loading import load_predictor
from idpose_core.noise_predictor import NoisePredictor
from idpose_ros.node.diagnostics import EstimatorStatus, diagnostic_array
from idpose_ros.node.estimate_run import EstimateRefused
from idpose_ros.node.estimation import Estimation
from idpose_ros.node.flight_recorder import FlightRecorder
from idpose_ros.node.goal_server import serve_goals
from idpose_ros.node.input_sync import InputSync
from idpose_ros.node.lifecycle import Lifecycle
from idpose_ros.node.model_holder import ModelHolder, ModelUnavailable
from idpose_ros.node.node_state import NodeState
from idpose_ros.node.parameters import NodeSettings, current_values, declare_parameters, optical_from_imu
from idpose_ros.node.result_publisher import ResultPublisher
from idpose_ros.node.run_state import CancelCause, RunPhase
from idpose_ros.node.view_buffer import CaptureRefused, ViewBuffer
from idpose_ros.node.view_intake import ViewIntake, view_inputs_text

NODE_NAME = "idpose_estimator"
SHUTDOWN_TIMEOUT = 1.5  # s to let a cancelled estimate stop on Ctrl-C (the node must exit within 2 s)
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
        self._state = NodeState(current_values(self))
        settings = self._state.settings
        self._predictor_factory = predictor_factory
        self._buffer = ViewBuffer(settings.max_views)
        self._recorder = FlightRecorder(settings.record_dir, settings.record_max_bytes, self._buffer.snapshot,
                                        self.get_logger().info, self.get_logger().error)
        self._buffer.restore(self._recorder.start(settings.resume, {"node": self.get_fully_qualified_name()}))
        self._model = ModelHolder(self._load_model, self._model_unavailable)
        self._estimation = Estimation(self._state, self._model, self._buffer, self._recorder,
                                      ResultPublisher(self, settings.publish_tf), self.get_logger())
        self.add_post_set_parameters_callback(self._on_parameters_set)

        sync = InputSync(settings.gravity, optical_from_imu(settings), settings.imu_window, settings.input_tolerance)
        self._intake = ViewIntake(self, self._state, self._buffer, sync, self._recorder, self._estimation.views_kept)
        self._intake.subscribe()
        services = MutuallyExclusiveCallbackGroup()  # one request at a time, each answered at once
        for name, handler in (("capture", self._capture), ("estimate", self._estimate), ("cancel", self._cancel),
                              ("reset", self._reset)):
            self.create_service(Trigger, f"~/{name}", handler, qos_profile=SERVICE_QOS, callback_group=services)
        self._action = serve_goals(self, self._estimation, self._intake, SERVICE_QOS)
        # A plain publisher, not a lifecycle one: /diagnostics reports the node in every lifecycle state.
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_timer(settings.diagnostics_period, self._publish_diagnostics,
                          callback_group=MutuallyExclusiveCallbackGroup())

        self.get_logger().info(f"{NODE_NAME} up: capture_mode={settings.capture_mode}, max_views={settings.max_views},"
                               f" model_path={settings.model_path or '<embedded default>'}")
        if settings.autostart:
            self._autostart()

    # ----- lifecycle -------------------------------------------------------------------------------------------
    @property
    def lifecycle_state(self) -> Lifecycle:
        """The lifecycle state as the transition callbacks keep it (rclpy has no public accessor): unconfigured,
        inactive, active or finalized (or a transition's, while one runs: configuring, activating, ...)."""
        return self._state.lifecycle

    def _autostart(self) -> None:
        """configure, then activate: what `ros2 run` gives without a lifecycle manager."""
        if self.trigger_configure() != TransitionCallbackReturn.SUCCESS:
            self.get_logger().warning("autostart: configure failed; the node stays unconfigured")
        elif self.trigger_activate() != TransitionCallbackReturn.SUCCESS:
            self.get_logger().error("autostart: activate failed; the node stays inactive")

    def _entered(self, state: Lifecycle) -> TransitionCallbackReturn:
        """Record and log the state a transition ends in."""
        self._state.lifecycle = state
        self.get_logger().info(f"lifecycle: {state}")
        return TransitionCallbackReturn.SUCCESS

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Load the model (unless load_model_at_startup is false: then the first estimate loads it)."""
        self._state.lifecycle = Lifecycle.CONFIGURING
        if self._state.settings.load_model_at_startup:
            try:
                self._model.get()
            except ModelUnavailable:  # logged once by _model_unavailable
                self._state.lifecycle = Lifecycle.UNCONFIGURED
                return TransitionCallbackReturn.FAILURE
        return self._entered(Lifecycle.INACTIVE)

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Turn the lifecycle publishers on, then take images and goals."""
        self._state.lifecycle = Lifecycle.ACTIVATING
        super().on_activate(state)  # the lifecycle publishers, each of which succeeds
        return self._entered(Lifecycle.ACTIVE)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop taking images and goals (the node is no longer active from the transition's start); a running
        estimate is cancelled, and one that has just ended publishes before the publishers turn off. The model and
        the views stay."""
        self._state.lifecycle = Lifecycle.DEACTIVATING
        self._estimation.cancel(CancelCause.DEACTIVATE)
        self._estimation.wait(SHUTDOWN_TIMEOUT)
        super().on_deactivate(state)
        return self._entered(Lifecycle.INACTIVE)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Free the model (and the CUDA cache); the buffered views stay."""
        self._state.lifecycle = Lifecycle.CLEANINGUP
        self._estimation.wait(SHUTDOWN_TIMEOUT)
        if self._model.release():
            self.get_logger().info("cleanup: released the model")
        self._estimation.set_phase(RunPhase.IDLE)
        return self._entered(Lifecycle.UNCONFIGURED)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """From any state: cancel a running estimate, turn the publishers off and free the model."""
        self._state.lifecycle = Lifecycle.SHUTTINGDOWN
        self.stop()
        super().on_deactivate(state)  # rclpy turns lifecycle publishers off on deactivate only, not on shutdown
        self._model.release()
        return self._entered(Lifecycle.FINALIZED)

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Back to unconfigured from a transition that raised: the publishers off, the model freed."""
        self._state.lifecycle = Lifecycle.ERRORPROCESSING
        self.get_logger().error(f"lifecycle error in state '{state.label}': back to unconfigured")
        super().on_deactivate(state)  # as on_shutdown: rclpy leaves them on after an error
        self._model.release()
        return self._entered(Lifecycle.UNCONFIGURED)

    # ----- model -----------------------------------------------------------------------------------------------
    def _load_model(self) -> NoisePredictor:
        settings = self._state.settings
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
        self._estimation.set_phase(RunPhase.FAILED, reason)

    # ----- services (each answers at once: nothing here waits for the running job) ----------------------------------
    def _capture(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        if not self._state.active:
            response.success, response.message = False, f"the node is {self._state.lifecycle}, not active"
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
            run = self._estimation.start_on_buffer("~/estimate")
        except EstimateRefused as refusal:
            response.success, response.message = False, str(refusal)
            return response
        response.success = True
        response.message = f"estimating the poses of {len(run.views)} views (run {run.run_id})"
        return response

    def _cancel(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        run_id = self._estimation.cancel(CancelCause.CANCEL)
        if run_id is None:
            response.success, response.message = False, self._estimation.nothing_to_cancel()
            return response
        response.success = True
        response.message = f"cancelling the estimate (run {run_id}); the {len(self._buffer)} views stay buffered"
        return response

    def _reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """Cancel a running estimate (its result is dropped whenever it stops) and drop every view, at once."""
        run_id = self._estimation.cancel(CancelCause.RESET)
        dropped = self._buffer.clear()
        self._recorder.event("reset", dropped=dropped)
        cancelled = "" if run_id is None else f" and cancelled the estimate (run {run_id})"
        self.get_logger().info(f"reset: dropped {dropped} views{cancelled}")
        response.success = True
        response.message = f"dropped {dropped} views" + (" (cancelled the running estimate)" if cancelled else "")
        return response

    # ----- status and parameters ------------------------------------------------------------------------------------
    def status(self) -> EstimatorStatus:
        """A consistent snapshot of what /diagnostics reports."""
        progress = self._estimation.progress
        run = self._estimation.snapshot()
        return EstimatorStatus(
            state=run.phase, run_id=run.run_id, views_buffered=len(self._buffer), max_views=self._buffer.max_views,
            model=self._model.describe(), lifecycle=self._state.lifecycle,
            images_received=self._intake.images_received,
            stage=progress.stage if progress else "", progress_percent=progress.percent if progress else 0.0,
            last_error=run.last_error, last_run_seconds=run.last.seconds, scores=run.last.scores,
            ambiguous=run.last.ambiguous, inputs=run.last.inputs, recording=self._recorder.status())

    def _publish_diagnostics(self) -> None:
        self._recorder.flush()  # the views it counts are in the recording
        hardware_id = f"{self.get_fully_qualified_name()} ({self._state.settings.device})"
        self._diagnostics_pub.publish(diagnostic_array(self.status(), hardware_id, self.get_clock().now().to_msg()))

    def _on_parameters_set(self, parameters: list[Parameter]) -> None:
        """Refresh the cached values and settings; a new ``max_views`` applies to the buffer at once."""
        self._state.update(current_values(self))
        if any(parameter.name == "max_views" for parameter in parameters):
            self._buffer.max_views = self._state.settings.max_views

    def stop(self, timeout: float = SHUTDOWN_TIMEOUT) -> bool:
        """Cancel a running estimate and wait up to ``timeout`` s; True when nothing is left running."""
        if self._estimation.cancel(CancelCause.SHUTDOWN) is not None:
            self.get_logger().info("shutting down: cancelling the running estimate")
        stopped = self._estimation.wait(timeout)
        self._recorder.close()
        return stopped
