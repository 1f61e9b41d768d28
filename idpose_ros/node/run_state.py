"""The node's one estimate run: its phase, id and cancel cause, and the last result's figures, behind one lock.

One lock, so that a run that ends at once cannot be overwritten by its own start, and so that a status read
sees the phase, the run id and the error of the same moment.
"""
from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum

from idpose_interfaces.action import EstimatePoses
from idpose_ros.node.estimate_run import EstimateRefused, EstimateRun

Result = EstimatePoses.Result


class RunPhase(StrEnum):
    """Where the node's estimate run is; /diagnostics reports the value."""

    IDLE = "idle"
    ESTIMATING = "estimating"
    CANCELLING = "cancelling"  # a cancelled estimate is stopping
    FAILED = "failed"  # the last estimate or the model load failed

    @property
    def running(self) -> bool:
        """A run is still on the worker: no new one can start."""
        return self in (RunPhase.ESTIMATING, RunPhase.CANCELLING)


class CancelCause(StrEnum):
    """What cancelled an estimate: the log, the cancelled result's message and the recording's cancel event name
    it by the value."""

    CANCEL = "~/cancel"
    RESET = "~/reset"  # the views are dropped too
    GOAL = "an EstimatePoses cancel"
    DEACTIVATE = "deactivate"
    SHUTDOWN = "shutdown"


@dataclass(frozen=True)
class LastResult:
    """What the last published result said: its seconds, per-view scores and ambiguity, and what it read off its
    views (``diagnostics.result_inputs``)."""

    seconds: float | None = None
    scores: tuple[float, ...] = ()
    ambiguous: tuple[bool, ...] = ()
    inputs: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class RunSnapshot:
    """The run state at one moment."""

    phase: RunPhase
    run_id: int  # of the running or the last estimate (0 before the first)
    last_error: str
    last: LastResult


class RunState:
    """The phase of the node's estimate run, its id, what cancelled it, the last error and the last result."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._phase = RunPhase.IDLE
        self._run_id = 0
        self._cancelled_by: CancelCause | None = None
        self._last_error = ""
        self._last = LastResult()

    def snapshot(self) -> RunSnapshot:
        with self._lock:
            return RunSnapshot(self._phase, self._run_id, self._last_error, self._last)

    @property
    def run_id(self) -> int:
        with self._lock:
            return self._run_id

    @property
    def cancelled_by(self) -> CancelCause | None:
        """What cancelled the current (or last cancelled) run; None before the first cancel."""
        with self._lock:
            return self._cancelled_by

    def start(self, new_run: Callable[[int], EstimateRun], launch: Callable[[EstimateRun], str | None]
              ) -> EstimateRun:
        """Start the next run: ``new_run(run_id)`` builds it, ``launch(run)`` hands it to the worker and returns
        None, or why the worker refused it. EstimateRefused (BUSY) while a run is on the worker, or refused."""
        with self._lock:
            if self._phase.running:
                verb = "running" if self._phase is RunPhase.ESTIMATING else "stopping after a cancel"
                raise EstimateRefused(Result.BUSY, f"busy: the estimate (run {self._run_id}) is {verb}")
            run = new_run(self._run_id + 1)
            refusal = launch(run)
            if refusal is None:
                self._run_id, self._phase, self._last_error = run.run_id, RunPhase.ESTIMATING, ""
        if refusal is not None:
            raise EstimateRefused(Result.BUSY, refusal)
        return run

    def cancel(self, cause: CancelCause, stop: Callable[[], bool]) -> int | None:
        """Mark the running estimate cancelled by ``cause`` if ``stop()`` (asking the worker) succeeds; its run id,
        or None when no estimate is running."""
        with self._lock:
            if self._phase is not RunPhase.ESTIMATING or not stop():
                return None
            self._phase, self._cancelled_by = RunPhase.CANCELLING, cause
            return self._run_id

    def nothing_to_cancel(self) -> str:
        """Why a cancel found nothing to stop."""
        with self._lock:
            if self._phase is RunPhase.CANCELLING:
                return f"the estimate (run {self._run_id}) is already stopping"
            return "no estimate is running"

    def set_phase(self, phase: RunPhase, error: str = "") -> None:
        with self._lock:
            self._phase, self._last_error = phase, error

    def finish(self, run: EstimateRun, phase: RunPhase, result: EstimatePoses.Result,
               last: LastResult | None = None) -> None:
        """End ``run`` with ``result`` (``last``: a published result's figures); the phase and the error follow
        unless a later run has started meanwhile."""
        with self._lock:
            if last is not None:
                self._last = last
            if run.run_id == self._run_id:
                self._phase = phase
                self._last_error = {Result.SUCCEEDED: "", Result.CANCELED: "cancelled"}.get(
                    result.error_code, result.error_message)
        run.finish(result)
