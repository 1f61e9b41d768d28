"""The estimator's /diagnostics message: state, level, progress, buffer, model and per-view scores."""
import numpy as np
import torch
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus

from idpose_core.next_view import NextView
from idpose_core.pipeline import PipelineResult, ViewReport
from idpose_core.preprocessing import PreprocessedViews
from idpose_core.solver import SolverResult
from idpose_ros.node.diagnostics import STATUS_NAME, EstimatorStatus, border_warning, diagnostic_array, result_inputs


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


def three_view_result(touching: tuple[bool, bool, bool], ambiguous: tuple[bool, bool]) -> PipelineResult:
    """A three-view result whose views' masks touch the border as ``touching`` says."""
    flags = (False, *ambiguous)
    reports = [ViewReport("depth", "", None, None, 0.5, touches_border=t, reliable=not (t or a))
               for t, a in zip(touching, flags)]
    masks = [np.ones((8, 8), dtype=bool)] * 3
    solved = SolverResult(np.zeros((2, 3)), np.zeros(2), np.full((2, 3), np.nan), np.full(2, np.nan),
                          np.array(ambiguous), np.ones(2), 0, 0)
    return PipelineResult(np.tile(np.eye(4), (3, 1, 1)), np.full((3, 4, 4), np.nan), solved,
                          PreprocessedViews(torch.zeros(3, 3, 4, 4), masks, ["depth"] * 3, [""] * 3, [(0, 0, 8)] * 3,
                                            [1.0] * 3),
                          masks, reports, 90.0, "parameter", 0.5, "depth",
                          NextView(np.array([1.0, 3.0, 0.5]), np.eye(4), 0.5, "coverage", None))


def test_the_border_flag_and_reliability_are_diagnostic_values_and_name_the_view_in_a_warning():
    result = three_view_result((False, False, True), (True, False))
    kv = result_inputs(result)
    assert [kv[f"view_{k}_touches_border"] for k in range(3)] == ["false", "false", "true"]
    assert [kv[f"view_{k}_reliable"] for k in range(3)] == ["true", "false", "false"]
    warning = border_warning(result)
    assert "view 2" in warning and "border" in warning and "view 1" not in warning
    assert border_warning(three_view_result((False, False, False), (True, True))) is None
    assert "view 0 (the anchor" in border_warning(three_view_result((True, False, False), (False, False)))
