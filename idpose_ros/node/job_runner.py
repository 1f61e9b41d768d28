"""The node's one long job at a time (an estimate) on a thread of its own, cancellable.

Image callbacks and services keep running on the executor while the worker computes; the job
gets a ``progress(stage, done, total)`` callback and a ``threading.Event`` to stop on.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from idpose_core.solver import Progress

Job = Callable[[Progress, threading.Event], Any]

LOG_EVERY_PERCENT = 10


class JobStatus(StrEnum):
    """How a job ended; a cancel request wins over a job that raised or finished meanwhile."""

    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELLED = "cancelled"


@dataclass(frozen=True)
class Outcome:
    """How a job ended (``status``), after how many seconds, with its value or its error."""

    task: str
    status: JobStatus
    seconds: float
    value: Any = None
    error: str = ""


@dataclass(frozen=True)
class JobProgress:
    """The running job's current stage and how far it is through that stage."""

    task: str
    stage: str
    percent: float


class JobRunner:
    """Runs jobs on a daemon thread, one at a time; ``log`` receives a line at every 10 % of a stage."""

    def __init__(self, log: Callable[[str], None]) -> None:
        self._log = log
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._active = False
        self._cancel = threading.Event()
        self._progress: JobProgress | None = None
        self._logged_step = -1

    @property
    def progress(self) -> JobProgress | None:
        """None when idle."""
        return self._progress

    @property
    def busy(self) -> bool:
        """True while a job computes (its ``on_done`` may still be finishing after that)."""
        return self._active

    def start(self, task: str, job: Job, on_done: Callable[[Outcome], None]) -> str | None:
        """Start ``job`` unless one is running; returns None when started, else the reason why not.

        ``on_done`` runs on the worker thread with the ``Outcome`` (a job that raises after a
        cancel request counts as cancelled).
        """
        with self._lock:
            if self._active:
                return f"busy: {self._progress.task if self._progress else 'a job'} is running"
            self._cancel = threading.Event()
            self._progress = JobProgress(task, "starting", 0.0)
            self._logged_step = -1
            self._active = True
            self._thread = threading.Thread(
                target=self._run, args=(task, job, on_done, self._cancel), name=f"idpose-{task}", daemon=True)
            self._thread.start()
            return None

    def cancel(self) -> bool:
        """Ask the running job to stop; True if one was running."""
        with self._lock:
            if self._active:
                self._cancel.set()
            return self._active

    def wait(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s for the running job (and its ``on_done``); True if none is left."""
        with self._lock:
            thread = self._thread
        if thread is None or thread is threading.current_thread():
            return True
        thread.join(timeout)
        return not thread.is_alive()

    def _report(self, task: str, stage: str, done: int, total: int) -> None:
        percent = 100.0 * done / total if total > 0 else 100.0
        step = int(percent // LOG_EVERY_PERCENT)
        previous = self._progress
        self._progress = JobProgress(task, stage, percent)
        if previous is None or previous.stage != stage:
            self._logged_step = -1
        if step > self._logged_step:
            self._logged_step = step
            self._log(f"{task}: {stage} {percent:.0f} % ({done}/{total})")

    def _run(self, task: str, job: Job, on_done: Callable[[Outcome], None], cancel: threading.Event) -> None:
        started = time.monotonic()
        value, error = None, ""
        try:
            value = job(lambda stage, done, total: self._report(task, stage, done, total), cancel)
        except Exception as exc:  # the job's failure is reported, never lost with the thread
            error = f"{type(exc).__name__}: {exc}"
        with self._lock:  # decided under the lock: a cancel() that returned True always wins
            self._active = False
            self._progress = None
            if cancel.is_set():
                value, error = None, "cancelled"
        status = JobStatus.CANCELLED if cancel.is_set() else JobStatus.FAILED if error else JobStatus.SUCCEEDED
        on_done(Outcome(task, status, time.monotonic() - started, value, error))
