"""A flight recording as a data-set input: each recorded result is one estimate, with the node's answer beside it.

The recording is read as ``evaluate_bag`` reads one (``evaluation.recording``): one task per published
result whose views all have ground truth, on the views it was estimated on (its n, not the protocol's
view counts). The fresh estimate runs on a worker like any other; the published result is scored on
the driver with the same task (row ``LIVE_METHOD``), so the report aggregates both over the data set.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

from idpose_core.evaluation.protocol import EstimateTask, EvaluationProtocol
from idpose_core.view_input import ViewInput
from idpose_ros.evaluation.bag_views import load_views
from idpose_ros.evaluation.ground_truth import GroundTruthOptions
from idpose_ros.evaluation.recording import LIVE_METHOD, RecordedEstimates, live_outcome, open_recording


class RecordingInput:
    """One recording file (a session's segment): its recorded results, each estimated again and as published."""

    kind = "recording"

    def __init__(self, path: Path, ground_truth: GroundTruthOptions):
        """Reads the recording; BagError when it is unreadable or was left unsealed by a kill."""
        self.path = Path(path)
        self.name = str(self.path.resolve())
        self.dataset = self.path.resolve().parent.name
        self.recorded: RecordedEstimates = open_recording(self.path, ground_truth, seed=0)

    def plan(self, protocol: EvaluationProtocol) -> list[EstimateTask]:
        """One task per scorable recorded result, on its own views; the protocol's seed seeds the random baseline."""
        return [replace(task, seed=protocol.seed) for task in self.recorded.tasks]

    def views(self, view_ids: set[int]) -> tuple[dict[int, ViewInput], dict[int, str]]:
        gt = self.recorded.ground_truth
        return load_views(self.path, gt.image_topic, view_ids, self.recorded.views, gt.inputs)

    def published(self, task: EstimateTask) -> dict[str, tuple[list[dict[str, Any]], dict[str, Any]]]:
        """The node's own result for this task, scored: ``{LIVE_METHOD: (pair records, row)}``."""
        return {LIVE_METHOD: live_outcome(task, self.recorded.live[task.index])}

    def summary(self) -> dict[str, Any]:
        recorded = self.recorded
        return {"views": len(recorded.views.views), "usable": len(recorded.views.pool),
                "skipped": len(recorded.views.skipped), "results": len(recorded.tasks) + len(recorded.left_out),
                "left_out": recorded.left_out}
