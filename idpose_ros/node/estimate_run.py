"""One estimate as the node runs it, whoever started it (``~/estimate``, an automatic start or an
``EstimatePoses`` goal): its views, live progress and typed result; and why one could not start."""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import Any

from idpose_core.solver import estimate_fraction
from idpose_interfaces.action import EstimatePoses
from idpose_ros.node.view_buffer import View

Result = EstimatePoses.Result
ETA_AFTER = 0.2  # share of the estimate done before seconds_remaining is extrapolated (negative before)


class EstimateRefused(Exception):
    """An estimate did not start: ``code`` is an ``EstimatePoses.Result`` error code, the message says why."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


def refusal_result(refusal: EstimateRefused, run_id: int = 0) -> EstimatePoses.Result:
    return Result(error_code=refusal.code, error_message=str(refusal), run_id=run_id)


@dataclass
class EstimateRun:
    """A started estimate; ``finished`` is set once ``result`` holds how it ended."""

    run_id: int
    views: list[View]
    frame_id: str
    values: dict[str, Any] = field(default_factory=dict)  # the parameter values it runs on
    started: float = field(default_factory=time.monotonic)
    stage: str = "preprocessing"
    fraction: float = 0.0
    forward_samples: int = 0
    result: EstimatePoses.Result | None = None
    finished: threading.Event = field(default_factory=threading.Event)

    def on_progress(self, stage: str, done: int, total: int) -> None:
        """The solver's ``progress`` callback: the stage and how far the whole estimate is."""
        self.stage, self.fraction = stage, max(self.fraction, estimate_fraction(stage, done, total))

    def on_samples(self, forward: int, backward: int) -> None:
        """The solver's ``samples`` callback."""
        self.forward_samples = forward

    def feedback(self) -> EstimatePoses.Feedback:
        """Where the estimate is now; seconds_remaining extrapolates the time spent (negative until ETA_AFTER)."""
        elapsed = time.monotonic() - self.started
        remaining = elapsed * (1.0 - self.fraction) / self.fraction if self.fraction >= ETA_AFTER else -1.0
        return EstimatePoses.Feedback(stage=self.stage, progress=self.fraction, forward_samples=self.forward_samples,
                                      seconds_elapsed=elapsed, seconds_remaining=remaining)

    def finish(self, result: EstimatePoses.Result) -> None:
        self.result = result
        self.finished.set()
