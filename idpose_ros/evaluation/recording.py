"""Evaluating a flight recording: the node's own estimates, as it made them live, beside a fresh estimate.

A recording is read like any bag through its recorded topics (``/idpose_recorder/image`` and the
inputs recorded with each view, world up from its view event); its ground truth comes from /tf (where
the recorder had it) or a ``--gt-topic``. Every recorded result whose views all have ground truth is
one estimate: the fresh one runs the evaluator's estimator on those views, the live one is the
result the node published, scored the same way (row ``as estimated live``). The fresh estimate takes
the anchor's polar angle and distance from the ground truth as every evaluation does; the live one
took them from the node's parameters (or gravity and depth), so position errors may differ in scale.
"""
from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from idpose_core.evaluation.estimator import ViewSetEstimate
from idpose_core.evaluation.object_frame import object_frame_c2w
from idpose_core.evaluation.protocol import EstimateTask, EvaluationProtocol, tasks_for_picks
from idpose_core.evaluation.results import Evaluation, evaluate_tasks
from idpose_core.evaluation.run import run_estimate
from idpose_core.view_input import ViewInput
from idpose_ros.estimate_result import view_set_estimate
from idpose_ros.evaluation.bag_evaluation import BagEvaluation
from idpose_ros.evaluation.bag_io import BagError
from idpose_ros.evaluation.bag_views import BagViews, load_views
from idpose_ros.evaluation.ground_truth import GroundTruthOptions, read_views
from idpose_ros.recording.log_format import IMAGE_TOPIC, INPUT_TOPICS, Recording, read_recording
from idpose_ros.recording.mcap_log import RecordingUnreadable

LIVE_METHOD = "as estimated live"


def recording_ground_truth(recording: Recording, ground_truth: GroundTruthOptions) -> GroundTruthOptions:
    """``ground_truth`` on the recorded topics: the image topic, and each input every view was kept with."""
    views = [event for event in recording.events if event["event"] == "view"]
    every = {kind for kind in INPUT_TOPICS if views and all(kind in event["inputs"] for event in views)}
    topics = {f"{kind}_topic": INPUT_TOPICS[kind] if kind in every else None for kind in INPUT_TOPICS}
    return replace(ground_truth, image_topic=IMAGE_TOPIC, extras=replace(ground_truth.extras, **topics))


def _with_gravity(views: BagViews, recording: Recording) -> BagViews:
    """World up per view as the node had it (its view event), in place of a gravity topic."""
    ups = {event["stamp"]: event["gravity_up"] for event in recording.events if event["event"] == "view"}
    stamps = {info.view_id: info.stamp for info in views.views}
    extras = {view_id: replace(sources, gravity_up=None if ups.get(stamps[view_id]) is None
                               else np.asarray(ups[stamps[view_id]], dtype=np.float64))
              for view_id, sources in views.extras.items()}
    return replace(views, extras=extras)


def recorded_tasks(recording: Recording, views: BagViews, ground_truth: GroundTruthOptions, seed: int
                   ) -> tuple[list[EstimateTask], list[ViewSetEstimate], list[str]]:
    """One task per recorded result whose views all have ground truth, the result as the evaluators take it, and
    why any other result is left out."""
    by_stamp: dict[int, int] = {}
    for info in views.views:
        by_stamp.setdefault(info.stamp, info.view_id)
    tasks, live, left_out = [], [], []
    for recorded in recording.results:
        pick = [by_stamp.get(stamp) for stamp in recorded.view_stamps]
        missing = [k for k, view_id in enumerate(pick) if view_id not in views.world_from_camera]
        if missing:
            left_out.append(f"run {recorded.result.run_id}: views {missing} are not in the recording or have no "
                            "ground truth")
            continue
        cameras = object_frame_c2w(np.stack([views.world_from_camera[v] for v in pick]), ground_truth.object_center,
                                   ground_truth.up)
        (task,) = tasks_for_picks([pick], [cameras], [len(pick)], seed)
        tasks.append(replace(task, sample=len(tasks), index=len(tasks)))
        live.append(view_set_estimate(recorded.result))
    return tasks, live, left_out


class _Published:
    """The result the node published, handed to ``run_estimate`` as if estimated again."""

    description = {"mode": "live"}
    values: dict = {}

    def __init__(self, estimate: ViewSetEstimate) -> None:
        self._estimate = estimate

    def __call__(self, views: Sequence[ViewInput], anchor_polar_deg: float, object_distance: float,
                 progress=None) -> ViewSetEstimate:
        return self._estimate

    def close(self) -> None:
        """Nothing to release."""


def live_outcome(task: EstimateTask, estimate: ViewSetEstimate) -> tuple[list[dict], dict]:
    """(pair records, row) of the published ``estimate`` scored as ``run_estimate`` scores a fresh one."""
    outcome = run_estimate(_Published(estimate), task, [])
    return outcome.records, outcome.row


@dataclass
class RecordedEstimates:
    """A flight recording opened for evaluation: its ground truth on the recorded topics, its views, one task per
    scorable recorded result with that result (``live``, in task order), and why any other result is left out."""

    path: Path
    ground_truth: GroundTruthOptions
    views: BagViews
    tasks: list[EstimateTask]
    live: list[ViewSetEstimate]
    left_out: list[str]


def open_recording(path: Path, ground_truth: GroundTruthOptions, seed: int) -> RecordedEstimates:
    """Read a recording's views, ground truth and results; BagError when it cannot be read or has no end."""
    try:
        recording = read_recording(path)
    except (RecordingUnreadable, ValueError) as err:
        raise BagError(f"{str(path)!r} is not a readable flight recording: {err}") from None
    if not recording.scan.sealed:
        raise BagError(f"{str(path)!r} has no end (the node was killed while recording): seal it with "
                       f"`ros2 run idpose_ros seal_recording {path}`, or start the node on its record_dir once")
    gt = recording_ground_truth(recording, ground_truth)
    views = _with_gravity(read_views(path, gt), recording)
    tasks, live, left_out = recorded_tasks(recording, views, gt, seed)
    return RecordedEstimates(Path(path), gt, views, tasks, live, left_out)


def evaluate_recording(path: Path, estimator, ground_truth: GroundTruthOptions | None = None,
                       protocol: EvaluationProtocol | None = None, show_progress: bool = True) -> BagEvaluation:
    """Each recorded result estimated again by ``estimator`` and scored beside the result itself (``LIVE_METHOD``);
    BagError when the recording cannot be read or no result can be scored."""
    started = time.perf_counter()
    protocol = protocol or EvaluationProtocol()
    recorded = open_recording(path, ground_truth or GroundTruthOptions(), protocol.seed)
    tasks, gt = recorded.tasks, recorded.ground_truth
    if not tasks:
        reasons = "; ".join(recorded.left_out) or "it holds no published result"
        raise BagError(f"no recorded estimate of {str(path)!r} can be scored: {reasons}")
    run = BagEvaluation(**Evaluation.planned(tasks, protocol, estimator), bag=Path(path), ground_truth=gt,
                        views=recorded.views)
    used = {v for task in tasks for v in task.pick}
    decoded, unusable = load_views(path, gt.image_topic, used, recorded.views, gt.inputs)
    evaluate_tasks(run, estimator, tasks, decoded, unusable, show_progress, name="evaluate_bag")
    for reason in recorded.left_out:
        print(f"evaluate_bag: left out {reason}", file=sys.stderr)
    for task, estimate in zip(tasks, recorded.live):
        if all(v in decoded for v in task.views):
            records, row = live_outcome(task, estimate)
            run.baseline_records.setdefault(LIVE_METHOD, []).extend(records)
            run.baseline_estimates.setdefault(LIVE_METHOD, []).append(row)
    run.baselines = (*run.baselines, LIVE_METHOD)
    run.seconds = time.perf_counter() - started
    return run
