"""The node's run state on its own: one run at a time, cancels, and a late finish that must not overwrite a newer
run's phase."""
import pytest

from idpose_interfaces.action import EstimatePoses
from idpose_ros.node.estimate_run import EstimateRefused, EstimateRun
from idpose_ros.node.run_state import LastResult, RunPhase, RunState

Result = EstimatePoses.Result


def start(state: RunState, refusal: str | None = None) -> EstimateRun:
    return state.start(lambda run_id: EstimateRun(run_id, [], "anchor"), lambda run: refusal)


def test_one_run_at_a_time_numbered_from_one():
    state = RunState()
    assert state.snapshot().phase is RunPhase.IDLE and state.run_id == 0
    run = start(state)
    assert run.run_id == 1 and state.snapshot().phase is RunPhase.ESTIMATING
    with pytest.raises(EstimateRefused, match=r"busy: the estimate \(run 1\) is running") as refused:
        start(state)
    assert refused.value.code == Result.BUSY and state.run_id == 1
    state.finish(run, RunPhase.IDLE, Result(error_code=Result.SUCCEEDED), LastResult(2.0, (0.1,), (False,)))
    snapshot = state.snapshot()
    assert (snapshot.phase, snapshot.last_error, snapshot.last.seconds) == (RunPhase.IDLE, "", 2.0)
    assert run.finished.is_set() and start(state).run_id == 2


def test_a_worker_refusal_starts_nothing():
    state = RunState()
    with pytest.raises(EstimateRefused, match="worker busy") as refused:
        start(state, refusal="worker busy")
    assert refused.value.code == Result.BUSY
    assert (state.snapshot().phase, state.run_id) == (RunPhase.IDLE, 0)


def test_cancel_marks_the_running_estimate_once_and_names_its_cause():
    state = RunState()
    assert state.cancel("~/cancel", lambda: True) is None and state.nothing_to_cancel() == "no estimate is running"
    run = start(state)
    assert state.cancel("~/cancel", lambda: False) is None, "the worker did not take the cancel"
    assert state.cancel("~/reset", lambda: True) == run.run_id
    assert state.snapshot().phase is RunPhase.CANCELLING and state.cancelled_by == "~/reset"
    assert state.nothing_to_cancel() == "the estimate (run 1) is already stopping"
    with pytest.raises(EstimateRefused, match="stopping after a cancel"):
        start(state)
    state.finish(run, RunPhase.IDLE, Result(error_code=Result.CANCELED, error_message="cancelled by ~/reset"))
    assert (state.snapshot().phase, state.snapshot().last_error) == (RunPhase.IDLE, "cancelled")


def test_a_late_finish_of_an_older_run_leaves_the_newer_one_running():
    state = RunState()
    first = start(state)
    state.finish(first, RunPhase.FAILED, Result(error_code=Result.FAILED, error_message="boom"))
    assert state.snapshot().last_error == "boom"
    second = start(state)
    state.finish(first, RunPhase.IDLE, Result(error_code=Result.SUCCEEDED))
    assert state.snapshot().phase is RunPhase.ESTIMATING and state.run_id == second.run_id
