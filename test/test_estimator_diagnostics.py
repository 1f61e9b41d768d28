"""The estimator's /diagnostics message: state, level, progress, buffer, model and per-view scores."""
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus

from idpose_ros.node.diagnostics import STATUS_NAME, EstimatorStatus, diagnostic_array


def values(status: EstimatorStatus) -> tuple[DiagnosticStatus, dict[str, str]]:
    array = diagnostic_array(status, "idpose_estimator (cpu)", Time(sec=5, nanosec=6))
    assert (array.header.stamp.sec, array.header.stamp.nanosec) == (5, 6)
    (entry,) = array.status
    assert entry.name == STATUS_NAME and entry.hardware_id == "idpose_estimator (cpu)"
    return entry, {kv.key: kv.value for kv in entry.values}


def test_an_estimate_in_progress_reports_stage_and_percent():
    entry, kv = values(EstimatorStatus(state="estimating", run_id=4, views_buffered=3, max_views=8, model="loaded",
                                       stage="refine", progress_percent=42.25, images_received=310))
    assert entry.level == DiagnosticStatus.OK and entry.message == "estimating: refine 42 %"
    assert (kv["state"], kv["run_id"], kv["stage"], kv["progress_percent"], kv["views_buffered"],
            kv["max_views"], kv["images_received"]) == ("estimating", "4", "refine", "42.2", "3", "8", "310")


def test_a_cancelled_estimate_that_is_still_stopping_is_not_an_error():
    entry, kv = values(EstimatorStatus(state="cancelling", run_id=2, views_buffered=0, max_views=8, model="loaded"))
    assert entry.level == DiagnosticStatus.OK and entry.message == "cancelling, 0 views buffered"
    assert kv["state"] == "cancelling" and kv["run_id"] == "2"


def test_a_finished_run_reports_time_and_per_view_scores():
    entry, kv = values(EstimatorStatus(state="idle", run_id=2, views_buffered=3, max_views=8, model="loaded",
                                       last_run_seconds=12.3456, scores=(0.5, 0.25), ambiguous=(False, True)))
    assert entry.level == DiagnosticStatus.OK and entry.message == "idle, 3 views buffered"
    assert kv["last_run_seconds"] == "12.346"
    assert (kv["view_1_score"], kv["view_1_ambiguous"], kv["view_2_score"], kv["view_2_ambiguous"]) == (
        "0.5", "false", "0.25", "true")
    assert "view_3_score" not in kv


def test_failures_are_errors():
    failed, kv = values(EstimatorStatus(state="failed", run_id=1, views_buffered=2, max_views=8, model="loaded",
                                        last_error="PreprocessingError: view 1 has no object"))
    assert failed.level == DiagnosticStatus.ERROR and "view 1 has no object" in failed.message
    assert kv["last_error"] == "PreprocessingError: view 1 has no object"
    no_model, kv = values(EstimatorStatus(state="failed", run_id=0, views_buffered=0, max_views=8,
                                          model="unavailable: no model available: /x does not exist",
                                          last_error="no model available: /x does not exist"))
    assert no_model.level == DiagnosticStatus.ERROR and kv["model"].startswith("unavailable: ")
