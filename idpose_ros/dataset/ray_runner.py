"""Estimates on Ray: one actor per worker holds the model, one actor call per estimate, failures retried once.

The same code runs on a local Ray instance (started here, sized to the machine) and on a cluster
(``address``): the driver reads the inputs and ships each estimate's decoded views through Ray's
object store, so the workers need the Python environment and the model path, not the data.
"""
from __future__ import annotations

import os
import socket
from collections import deque
from collections.abc import Hashable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import ray
import torch
from ray.exceptions import RayActorError, RayError, RayTaskError

from idpose_core.evaluation.protocol import EstimateTask
from idpose_core.evaluation.run import EstimateOutcome, run_estimate
from idpose_core.view_input import ViewInput
from idpose_ros.evaluation.estimators import EstimatorOptions, make_estimator

WAIT_SECONDS = 1.0  # ray.wait slices: Ctrl-C is handled between them
SOURCE_ROOT = Path(__file__).resolve().parents[1]  # the folder holding idpose_ros, idpose_core, msg_adapters


class RunnerError(RuntimeError):
    """The estimates cannot run: no worker fits the cluster, or none could start (e.g. the model does not load)."""


@dataclass(frozen=True)
class WorkerResources:
    """How many workers (None: as many as the cluster holds) and what each reserves; torch runs on
    ``num_cpus`` threads in each."""

    workers: int | None = None
    num_cpus: int = 1
    num_gpus: float = 0.0


@dataclass(frozen=True)
class Job:
    """One estimate to run: its key (what results.jsonl knows it by), the task and its decoded views."""

    key: Hashable
    task: EstimateTask
    views: list[ViewInput]


@dataclass(frozen=True)
class JobResult:
    """A finished job: its outcome and the worker that produced it, or, after the last attempt, the error."""

    key: Hashable
    task: EstimateTask
    attempts: int
    outcome: EstimateOutcome | None = None
    worker: str | None = None
    error: str | None = None


class RayEstimatorActor:
    """The state of one Ray actor: the estimator with its model, loaded once, on ``threads`` torch threads."""

    def __init__(self, options: EstimatorOptions, threads: int):
        torch.set_num_threads(threads)
        self.estimator = make_estimator(options)
        self.name = f"{socket.gethostname()}:{os.getpid()}"

    def ready(self) -> str:
        """The worker's name (host:pid), once its model is loaded."""
        return self.name

    def estimate(self, task: EstimateTask, views: list[ViewInput], baselines: tuple[str, ...] = ()
                 ) -> tuple[EstimateOutcome, str]:
        """``run_estimate`` on this worker's estimator (and the named classical baselines), less the random
        baseline (the driver redraws it from the task's seed when it merges the report)."""
        outcome = run_estimate(self.estimator, task, views, baselines=baselines)
        return EstimateOutcome(outcome.records, [], outcome.row, outcome.predicted_c2w, outcome.baselines), self.name


@contextmanager
def ray_session(address: str | None = None) -> Iterator[None]:
    """Ray for this block: joins ``address`` (a running cluster), or starts a local instance sized to the machine;
    left as it is when this process is already connected (a notebook, a test)."""
    if ray.is_initialized():
        yield
        return
    ray.init(address=address, num_cpus=None if address else os.cpu_count(), include_dashboard=False,
             logging_level="WARNING")
    try:
        yield
    finally:
        ray.shutdown()


def worker_count(resources: WorkerResources) -> int:
    """``resources.workers``, or as many workers as the cluster's CPUs and GPUs hold (RunnerError for none)."""
    if resources.workers is not None:
        return resources.workers
    total = ray.cluster_resources()
    count = int(total.get("CPU", 0) // resources.num_cpus)
    if resources.num_gpus:
        count = min(count, int(total.get("GPU", 0) // resources.num_gpus))
    if count < 1:
        raise RunnerError(f"the cluster has {total.get('CPU', 0):g} CPUs and {total.get('GPU', 0):g} GPUs: no worker "
                          f"of {resources.num_cpus} CPUs and {resources.num_gpus:g} GPUs fits")
    return count


def error_text(err: RayError) -> str:
    """One line on a failed call: the estimate's own exception, or the last line of why its worker died."""
    if isinstance(err, RayTaskError) and not isinstance(err, RayActorError) and err.cause is not None:
        return f"{type(err.cause).__name__}: {err.cause}"
    lines = [line.strip() for line in str(err).splitlines() if line.strip()]
    return lines[-1] if lines else type(err).__name__


@dataclass
class _Attempt:
    """A job in flight: which try this is, and its views in the object store (kept for a retry)."""

    job: Job
    views: ray.ObjectRef
    number: int = 1


class EstimatorPool:
    """Workers on Ray; ``run(jobs)`` yields each job's result as it finishes.

    A failed estimate is tried ``retries`` more times, on whichever worker is free; a worker that dies
    during an estimate is replaced; a replacement that cannot start is not replaced again. Use as a
    context manager: the actors stop when the block ends, also on Ctrl-C.
    """

    def __init__(self, options: EstimatorOptions, resources: WorkerResources, retries: int = 1,
                 baselines: tuple[str, ...] = ()):
        self.options, self.resources, self.retries, self.baselines = options, resources, retries, baselines
        self._actors: list = []
        self._pending: dict = {}  # ObjectRef -> (actor, its _Attempt, or None for a ready() call)
        self._idle: deque = deque()
        self._retry: deque[_Attempt] = deque()
        self._started = False  # some worker has loaded the model

    def __enter__(self) -> EstimatorPool:
        return self

    def __exit__(self, *exc) -> None:
        for actor in self._actors:
            ray.kill(actor)
        self._actors.clear()
        self._pending.clear()

    def _start_worker(self) -> None:
        actor_class = ray.remote(RayEstimatorActor).options(
            num_cpus=self.resources.num_cpus, num_gpus=self.resources.num_gpus, max_restarts=0,
            runtime_env={"env_vars": {"PYTHONPATH": f"{SOURCE_ROOT}{os.pathsep}${{PYTHONPATH}}"}})
        actor = actor_class.remote(self.options, self.resources.num_cpus)
        self._actors.append(actor)
        self._pending[actor.ready.remote()] = (actor, None)

    def _dispatch(self, upcoming: Iterator[Job]) -> bool:
        """Give idle workers retries first, then new jobs; False once ``upcoming`` is exhausted."""
        while self._idle:
            if self._retry:
                attempt = self._retry.popleft()
            else:
                job = next(upcoming, None)
                if job is None:
                    return False
                attempt = _Attempt(job, ray.put(job.views))
            actor = self._idle.popleft()
            self._pending[actor.estimate.remote(attempt.job.task, attempt.views, self.baselines)] = (actor, attempt)
        return True

    def _failed(self, actor, attempt: _Attempt | None, err: RayError) -> JobResult | None:
        """Handle a failed call: drop a worker that did not start, replace one that died in an estimate, queue a
        retry; returns the final failure. RunnerError when the first workers cannot start (e.g. a bad model)."""
        if attempt is None:
            self._actors.remove(actor)
            ray.kill(actor)
            if not self._started:
                raise RunnerError(f"a worker could not start: {error_text(err)}")
            return None
        if isinstance(err, RayActorError):
            self._actors.remove(actor)
            self._start_worker()
        else:
            self._idle.append(actor)
        if attempt.number <= self.retries:
            attempt.number += 1
            self._retry.append(attempt)
            return None
        died = "the worker died: " if isinstance(err, RayActorError) else ""
        return JobResult(attempt.job.key, attempt.job.task, attempt.number, error=died + error_text(err))

    def run(self, jobs: Iterable[Job]) -> Iterator[JobResult]:
        """Run every job; results in completion order. Raises RunnerError when no worker can run them."""
        for _ in range(worker_count(self.resources)):
            self._start_worker()
        upcoming, exhausted = iter(jobs), False
        while True:
            exhausted = not self._dispatch(upcoming) or exhausted
            if not self._pending:
                if self._retry or not exhausted:
                    raise RunnerError("no worker left to run the remaining estimates")
                return
            done, _ = ray.wait(list(self._pending), num_returns=1, timeout=WAIT_SECONDS)
            for ref in done:
                actor, attempt = self._pending.pop(ref)
                try:
                    value = ray.get(ref)
                except RayError as err:
                    result = self._failed(actor, attempt, err)
                    if result is not None:
                        yield result
                    continue
                self._idle.append(actor)
                if attempt is None:
                    self._started = True
                else:
                    outcome, worker = value
                    yield JobResult(attempt.job.key, attempt.job.task, attempt.number, outcome, worker)
