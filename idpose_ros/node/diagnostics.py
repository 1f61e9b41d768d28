"""The estimator's health as a `diagnostic_msgs/DiagnosticArray` for `/diagnostics`."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from idpose_core.pipeline import PipelineResult
from idpose_ros.node.lifecycle import Lifecycle
from idpose_ros.node.run_state import RunPhase

STATUS_NAME = "idpose_estimator: estimation"


@dataclass(frozen=True)
class EstimatorStatus:
    """What the node reports: ``lifecycle`` its lifecycle state; ``state`` its ``RunPhase``: idle,
    estimating, cancelling (a cancelled estimate is stopping) or failed; ``run_id`` numbers the running or the
    last estimate (0 before the first), as ``~/estimate`` answered it; ``model`` as ``ModelHolder.describe``;
    ``images_received`` counts every image message."""

    state: RunPhase
    run_id: int
    views_buffered: int
    max_views: int
    model: str
    lifecycle: Lifecycle = Lifecycle.ACTIVE
    images_received: int = 0
    stage: str = ""
    progress_percent: float = 0.0
    last_error: str = ""
    last_run_seconds: float | None = None
    scores: tuple[float, ...] = field(default_factory=tuple)
    ambiguous: tuple[bool, ...] = field(default_factory=tuple)
    inputs: dict[str, str] = field(default_factory=dict)  # what the last result read off its views (result_inputs)
    recording: dict[str, str] = field(default_factory=dict)  # the flight recorder's (FlightRecorder.status)


def level(status: EstimatorStatus) -> bytes:
    """ERROR when the last estimate or the model load failed, WARN when the recording stopped, OK otherwise."""
    if status.state == RunPhase.FAILED:
        return DiagnosticStatus.ERROR
    return DiagnosticStatus.WARN if status.recording.get("recording", "").startswith("error") else DiagnosticStatus.OK


def summary(status: EstimatorStatus) -> str:
    if status.lifecycle != Lifecycle.ACTIVE and status.state != RunPhase.FAILED:
        return f"{status.lifecycle}, {status.views_buffered} views buffered"
    if status.state == RunPhase.ESTIMATING:
        return f"{status.state}: {status.stage} {status.progress_percent:.0f} %"
    if status.state == RunPhase.FAILED:
        return f"failed: {status.last_error}"
    return f"{status.state}, {status.views_buffered} views buffered"


def diagnostic_array(status: EstimatorStatus, hardware_id: str, stamp: Time) -> DiagnosticArray:
    """One DiagnosticStatus with the state, progress, buffer, model, last run and per-view scores."""
    values = {
        "lifecycle": str(status.lifecycle),
        "state": str(status.state),
        "run_id": str(status.run_id),
        "stage": status.stage,
        "progress_percent": f"{status.progress_percent:.1f}",
        "views_buffered": str(status.views_buffered),
        "max_views": str(status.max_views),
        "images_received": str(status.images_received),
        "model": status.model,
        "last_error": status.last_error,
        "last_run_seconds": "" if status.last_run_seconds is None else f"{status.last_run_seconds:.3f}",
    }
    for view, (score, ambiguous) in enumerate(zip(status.scores, status.ambiguous), start=1):
        values[f"view_{view}_score"] = f"{score:.6g}"
        values[f"view_{view}_ambiguous"] = str(bool(ambiguous)).lower()
    values.update(status.inputs)
    values.update(status.recording)
    entry = DiagnosticStatus(level=level(status), name=STATUS_NAME, message=summary(status),
                             hardware_id=hardware_id,
                             values=[KeyValue(key=k, value=v) for k, v in values.items()])
    array = DiagnosticArray(status=[entry])
    array.header.stamp = stamp
    return array


def result_inputs(result: PipelineResult) -> dict[str, str]:
    """Diagnostic values of what an estimate read off its views: where the anchor's polar angle and distance
    came from, and per view k (0 = the anchor) the mask method (and why a more trusted one was not used), a depth
    cut's confidence,
    whether the mask touches the image border and whether the pose is reliable, the roll and polar angle from
    gravity."""
    values = {"anchor_polar_deg": f"{result.anchor_polar_deg:.2f}", "anchor_polar_source": result.polar_source,
              "object_distance": f"{result.object_distance:.4f}", "object_distance_source": result.distance_source}
    for k, view in enumerate(result.views):
        values[f"view_{k}_mask"] = view.mask_method + (f" ({view.mask_note})" if view.mask_note else "")
        if math.isfinite(view.mask_confidence):
            values[f"view_{k}_mask_confidence"] = f"{view.mask_confidence:.2f}"
        values[f"view_{k}_touches_border"] = str(view.touches_border).lower()
        values[f"view_{k}_reliable"] = str(view.reliable).lower()
        if view.roll_deg is not None:
            values[f"view_{k}_roll_deg"] = f"{view.roll_deg:.2f}"
            values[f"view_{k}_polar_deg"] = f"{view.polar_deg:.2f}"
    return values


def border_warning(result: PipelineResult) -> str | None:
    """The warning for a published estimate whose views' masks touch the image border (their objects are likely
    cut off, so those poses are unreliable), naming the views as /diagnostics does (0 = the anchor); None when
    no mask does."""
    views = [k for k, view in enumerate(result.views) if view.touches_border]
    if not views:
        return None
    names = ", ".join("view 0 (the anchor: every pose is measured from it)" if k == 0 else f"view {k}" for k in views)
    return f"unreliable pose: the object mask of {names} touches the image border; the object may be cut off"
