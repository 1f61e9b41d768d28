"""The estimator's worker thread: one job at a time, cancellable, failures reported, progress logged."""
import re
import threading

import pytest

from idpose_ros.node.job_runner import JobRunner, Outcome

TIMEOUT = 10.0


class Recorder:
    """Collects log lines and the outcome the worker hands back."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.outcomes: list[Outcome] = []
        self.done = threading.Event()

    def on_done(self, outcome: Outcome) -> None:
        self.outcomes.append(outcome)
        self.done.set()


@pytest.fixture
def recorder() -> Recorder:
    return Recorder()


@pytest.fixture
def worker(recorder):
    worker = JobRunner(recorder.lines.append)
    yield worker
    worker.cancel()
    assert worker.wait(TIMEOUT)


def until_cancelled(started: threading.Event):
    """A job that runs until asked to stop, then raises like the solver does."""
    def job(progress, cancel):
        started.set()
        while not cancel.wait(0.01):
            pass
        raise RuntimeError("stopped on request")
    return job


def test_a_job_runs_and_hands_back_its_value(worker, recorder):
    assert worker.start("estimate", lambda progress, cancel: 42, recorder.on_done) is None
    assert recorder.done.wait(TIMEOUT)
    (outcome,) = recorder.outcomes
    assert (outcome.task, outcome.status, outcome.value, outcome.error) == ("estimate", "succeeded", 42, "")
    assert outcome.seconds >= 0 and not worker.busy and worker.progress is None


def test_a_second_job_is_refused_while_one_runs_and_cancel_stops_it(worker, recorder):
    started = threading.Event()
    assert worker.start("estimate", until_cancelled(started), recorder.on_done) is None
    assert started.wait(TIMEOUT) and worker.busy
    refusal = worker.start("estimate", lambda progress, cancel: 0, recorder.on_done)
    assert refusal is not None and "busy" in refusal and "estimate" in refusal
    assert worker.cancel()
    assert recorder.done.wait(TIMEOUT) and worker.wait(TIMEOUT)
    assert [(o.status, o.value, o.error) for o in recorder.outcomes] == [("cancelled", None, "cancelled")]
    assert not worker.cancel(), "nothing left to cancel"


def test_a_cancel_request_wins_even_when_the_job_finishes(worker, recorder):
    """A cancel() that returned True must never be followed by a published result."""
    release = threading.Event()
    started = threading.Event()

    def job(progress, cancel):
        started.set()
        release.wait(TIMEOUT)
        return "result"

    worker.start("estimate", job, recorder.on_done)
    assert started.wait(TIMEOUT) and worker.cancel()
    release.set()
    assert recorder.done.wait(TIMEOUT)
    assert recorder.outcomes[0].status == "cancelled" and recorder.outcomes[0].value is None


def test_a_failing_job_is_reported_with_the_exception(worker, recorder):
    def job(progress, cancel):
        raise FileNotFoundError("weights.ckpt is missing")

    worker.start("loading model", job, recorder.on_done)
    assert recorder.done.wait(TIMEOUT)
    (outcome,) = recorder.outcomes
    assert outcome.status == "failed" and outcome.error == "FileNotFoundError: weights.ckpt is missing"
    assert worker.start("estimate", lambda progress, cancel: 1, recorder.on_done) is None, "usable again"


def test_progress_is_logged_at_least_every_ten_percent_of_each_stage(worker, recorder):
    seen = []

    def job(progress, cancel):
        for stage, total in (("explore", 7), ("refine", 1000)):
            for done in range(total + 1):
                progress(stage, done, total)
                seen.append(worker.progress)
        return None

    worker.start("estimate", job, recorder.on_done)
    assert recorder.done.wait(TIMEOUT)
    logged = {}
    for line in recorder.lines:
        match = re.fullmatch(r"estimate: (\w+) (\d+) % \((\d+)/(\d+)\)", line)
        assert match, line
        logged.setdefault(match[1], []).append(int(match[2]))
    for stage in ("explore", "refine"):
        marks = logged[stage]
        assert marks[0] == 0 and marks[-1] == 100
        assert all(0 < later - earlier <= 15 for earlier, later in zip(marks, marks[1:])), marks
    assert len(logged["refine"]) == 11, "one line per 10 %, not one per step"
    assert seen[-1].stage == "refine" and seen[-1].percent == 100.0
