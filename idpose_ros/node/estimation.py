"""One estimate from start to result: the node's one estimate path, read top to bottom.

``start`` checks an estimate can run and hands it to the worker thread; ``_estimate`` runs the pipeline there;
``_finished`` takes its outcome: a published result (poses, markers, views, cloud, TF, the recording) or the reason
there is none. ``~/estimate`` (``start_on_buffer``), an ``EstimatePoses`` goal (``goal_server``) and a full buffer
(``views_kept``, with ``views_per_estimate``) all start here, and one ``RunState`` says which run is on.
"""
from __future__ import annotations

import threading
from functools import partial
from typing import Any

from rclpy.impl.rcutils_logger import RcutilsLogger
from std_msgs.msg import Header

from idpose_core.pipeline import PipelineResult, PipelineSettings, estimate_view_poses
from idpose_core.solver import Progress
from idpose_interfaces.action import EstimatePoses
from idpose_ros.estimate_result import result_message
from idpose_ros.node.diagnostics import border_warning, result_inputs
from idpose_ros.node.estimate_run import EstimateRefused, EstimateRun
from idpose_ros.node.flight_recorder import FlightRecorder
from idpose_ros.node.job_runner import JobProgress, JobRunner, JobStatus, Outcome
from idpose_ros.node.model_holder import ModelHolder
from idpose_ros.node.node_state import NodeState
from idpose_ros.node.parameters import pipeline_settings
from idpose_ros.node.result_publisher import ResultPublisher
from idpose_ros.node.run_state import CancelCause, LastResult, RunPhase, RunSnapshot, RunState
from idpose_ros.node.view_buffer import View, ViewBuffer

Result = EstimatePoses.Result
FALLBACK_FRAME = "idpose_anchor"  # frame of the poses when neither anchor_frame nor the anchor image names one


class Estimation:
    """Starts estimates of buffered or given views, runs them one at a time on a worker thread, publishes them."""

    def __init__(self, state: NodeState, model: ModelHolder, buffer: ViewBuffer, recorder: FlightRecorder,
                 results: ResultPublisher, logger: RcutilsLogger) -> None:
        self._state, self._model, self._buffer, self._recorder = state, model, buffer, recorder
        self._results, self._logger = results, logger
        self._jobs = JobRunner(logger.info)
        self._runs = RunState()

    # ----- starting ---------------------------------------------------------------------------------------------
    @property
    def values(self) -> dict[str, Any]:
        """The node's current parameter values: what an estimate runs on unless a goal names a preset."""
        return self._state.values

    def require_active(self, what: str) -> None:
        """EstimateRefused (NOT_ACTIVE, or MODEL_UNAVAILABLE after a failed load) unless the node is active."""
        if self._state.active:
            return
        if self._model.problem:
            raise EstimateRefused(Result.MODEL_UNAVAILABLE, self._model.problem)
        raise EstimateRefused(Result.NOT_ACTIVE,
                              f"the node is {self._state.lifecycle}, not active: {what} refused (activate it through "
                              "its lifecycle, or start it with autostart true)")

    def buffered_views(self) -> list[View]:
        """The views an estimate of the buffer takes, each in the recording before anyone hears of the estimate."""
        self._recorder.flush()
        views = self._buffer.snapshot()
        if len(views) < 2:
            raise EstimateRefused(Result.INVALID_GOAL, f"need at least 2 buffered views to estimate, have {len(views)}")
        return views

    def start_on_buffer(self, what: str) -> EstimateRun:
        """An estimate of the buffered views on the node's parameters (``what`` asked for it)."""
        self.require_active(what)
        return self.start(self.buffered_views(), self.values)

    def views_kept(self, count: int) -> None:
        """Start an estimate when the buffer reaches ``views_per_estimate``."""
        wanted = self._state.settings.views_per_estimate
        if wanted > 0 and count == wanted:
            try:
                self.start(self.buffered_views(), self.values)
            except EstimateRefused as refusal:
                self._logger.warning(f"automatic estimate not started: {refusal}")

    def start(self, views: list[View], values: dict[str, Any]) -> EstimateRun:
        """Start an estimate of ``views`` on these parameter values; EstimateRefused says why it did not start."""
        if self._model.problem:
            raise EstimateRefused(Result.MODEL_UNAVAILABLE, self._model.problem)
        pipeline = pipeline_settings(values)
        named_frame = values["anchor_frame"] or views[0].frame_id
        for index, view in enumerate(views):
            if view.pending:
                self._logger.warning(f"view {index + 1}: no {' or '.join(sorted(view.pending))} image matched its "
                                     "stamp; it is estimated without")
        run = self._runs.start(partial(EstimateRun, views=views, frame_id=named_frame or FALLBACK_FRAME,
                                       values=values), partial(self._launch, pipeline))
        self._logger.info(f"estimating the poses of {len(views)} views, run {run.run_id} ({pipeline.solver.variant}, "
                          f"{pipeline.solver.refine_steps_per_view} refinement steps per view)")
        if not named_frame:
            self._logger.warning(f"the anchor image has no header.frame_id and anchor_frame is not set: publishing "
                                 f"the poses in frame '{FALLBACK_FRAME}'")
        return run

    def _launch(self, pipeline: PipelineSettings, run: EstimateRun) -> str | None:
        """Hand ``run`` to the worker; None, or why the worker refused it."""
        return self._jobs.start("estimate", partial(self._estimate, pipeline, run), partial(self._finished, run))

    # ----- running (on the worker thread) ---------------------------------------------------------------------
    def _estimate(self, pipeline: PipelineSettings, run: EstimateRun, progress: Progress,
                  cancel: threading.Event) -> PipelineResult:
        predictor = self._model.get()  # waits for a load still running

        def report(stage: str, done: int, total: int) -> None:
            progress(stage, done, total)  # the log and /diagnostics
            run.on_progress(stage, done, total)  # the goal's feedback

        return estimate_view_poses(predictor, [view.input for view in run.views], pipeline, report, cancel,
                                   samples=run.on_samples)

    # ----- the outcome ------------------------------------------------------------------------------------------
    def _finished(self, run: EstimateRun, outcome: Outcome) -> None:
        """Publish a result, or log why there is none; then end the run."""
        if outcome.status is JobStatus.CANCELLED:
            self._cancelled(run, outcome)
        elif outcome.status is JobStatus.FAILED:
            self._failed(run, outcome)
        else:
            self._publish(run, outcome.value, outcome.seconds)

    def _cancelled(self, run: EstimateRun, outcome: Outcome) -> None:
        cause = self._runs.cancelled_by
        kept = ("its views were dropped" if cause is CancelCause.RESET
                else f"the {len(self._buffer)} buffered views stay for a retry")
        message = f"cancelled by {cause}; {kept}"
        self._logger.info(f"estimate (run {run.run_id}) stopped {outcome.seconds:.1f} s after it started, {message}")
        self._runs.finish(run, RunPhase.IDLE, Result(error_code=Result.CANCELED, error_message=message,
                                                     run_id=run.run_id))

    def _failed(self, run: EstimateRun, outcome: Outcome) -> None:
        if self._model.problem:  # already logged once, where the load failed
            self._runs.finish(run, RunPhase.FAILED, Result(error_code=Result.MODEL_UNAVAILABLE,
                                                           error_message=self._model.problem, run_id=run.run_id))
            return
        self._logger.error(f"estimate (run {run.run_id}) failed after {outcome.seconds:.1f} s: {outcome.error}; the "
                           f"{len(self._buffer)} buffered views are kept")
        self._runs.finish(run, RunPhase.FAILED, Result(error_code=Result.FAILED, error_message=outcome.error,
                                                       run_id=run.run_id))

    def _publish(self, run: EstimateRun, result: PipelineResult, seconds: float) -> None:
        headers = [Header(frame_id=view.frame_id, stamp=view.stamp) for view in run.views]
        message = result_message(result, headers, run.frame_id, run.run_id, seconds)
        self._recorder.result(message, run.values, run.views)  # recorded before anyone can see it
        self._results.publish(result, message, self._state.settings.tf_prefix)
        solved = result.solver_result
        last = LastResult(seconds, tuple(float(s) for s in solved.scores), tuple(bool(a) for a in solved.ambiguous),
                          result_inputs(result))
        self._runs.finish(run, RunPhase.IDLE, message, last)
        if warning := border_warning(result):
            self._logger.warning(warning)
        if solved.note:
            self._logger.warning(f"run {run.run_id}: {solved.note}")
        self._logger.info(f"published {len(result.poses)} poses in frame '{run.frame_id}' after {seconds:.1f} s "
                          f"({int(sum(last.ambiguous))} ambiguous)")

    # ----- cancelling and state -------------------------------------------------------------------------------------
    def cancel(self, cause: CancelCause) -> int | None:
        """Ask the running estimate to stop; its run id, or None when none is running."""
        run_id = self._runs.cancel(cause, self._jobs.cancel)
        if run_id is not None:
            self._recorder.event("cancel", run_id=run_id, by=cause)
        return run_id

    def nothing_to_cancel(self) -> str:
        """Why a cancel found nothing to stop."""
        return self._runs.nothing_to_cancel()

    def wait(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s for the running estimate to end; True when nothing is running."""
        return self._jobs.wait(timeout)

    @property
    def run_id(self) -> int:
        """The id of the running or the last estimate (0 before the first)."""
        return self._runs.run_id

    def snapshot(self) -> RunSnapshot:
        return self._runs.snapshot()

    @property
    def progress(self) -> JobProgress | None:
        """Where the running estimate is, for /diagnostics."""
        return self._jobs.progress

    def set_phase(self, phase: RunPhase, error: str = "") -> None:
        """The phase outside a run: FAILED with the reason when the model did not load, IDLE after cleanup."""
        self._runs.set_phase(phase, error)
