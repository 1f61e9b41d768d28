"""An evaluation in progress: every estimate's pair records, rows and cameras, the baselines', the failures."""
from __future__ import annotations

import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from tqdm import tqdm

from idpose_core.evaluation.estimator import ViewSetEstimator
from idpose_core.evaluation.protocol import EstimateTask, EvaluationProtocol
from idpose_core.evaluation.run import EstimateOutcome, check_baselines, run_estimate
from idpose_core.metrics import aggregate
from idpose_core.preprocessing import PreprocessingError
from idpose_core.view_input import ViewInput


@dataclass(kw_only=True)
class Evaluation:
    """What an evaluation measured: per-pair records, per-estimate rows, per-sample cameras, the random-pose
    baseline and the classical ``baselines`` on the same pairs (their records and rows by name), the estimates
    that could not run on their views, and what produced them (``estimator``: its description and node
    parameters)."""

    protocol: EvaluationProtocol
    estimator: dict[str, Any]
    picks: list[list[int]]
    view_counts: list[int]  # the requested counts that the views allow
    baselines: tuple[str, ...] = ()
    records: list[dict[str, Any]] = field(default_factory=list)
    random_records: list[dict[str, Any]] = field(default_factory=list)
    estimates: list[dict[str, Any]] = field(default_factory=list)
    true_cameras: dict[int, np.ndarray] = field(default_factory=dict)  # sample -> (k, 4, 4) OpenGL c2w
    predicted_cameras: dict[int, np.ndarray] = field(default_factory=dict)  # sample -> largest n's
    baseline_records: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    baseline_estimates: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    failures: list[dict[str, Any]] = field(default_factory=list)  # estimates refused for a view's content
    seconds: float = 0.0  # the whole evaluation's wall time, reading included

    @staticmethod
    def planned(tasks: Sequence[EstimateTask], protocol: EvaluationProtocol, estimator: ViewSetEstimator,
                baselines: Sequence[str] = ()) -> dict[str, Any]:
        """The fields an evaluation of these tasks starts with (pass them to the constructor)."""
        check_baselines(baselines)
        return {"protocol": protocol, "estimator": {**estimator.description, "node_parameters": estimator.values},
                "picks": list({task.sample: list(task.pick) for task in tasks}.values()),
                "view_counts": sorted({task.n for task in tasks}), "baselines": tuple(baselines)}

    @property
    def aggregates(self) -> dict[str, dict[str, float | int]]:
        return aggregate(self.records)

    @property
    def random_aggregates(self) -> dict[str, dict[str, float | int]]:
        """The same metrics for random guesses of the target cameras (``pairs`` counts guesses)."""
        return aggregate(self.random_records)

    def add(self, task: EstimateTask, outcome: EstimateOutcome) -> None:
        """Take in one estimate's outcome (the cameras plotted per sample are its largest n's)."""
        self.records.extend(outcome.records)
        self.random_records.extend(outcome.random_records)
        self.estimates.append(outcome.row)
        self.true_cameras[task.sample] = task.true_c2w
        self.predicted_cameras[task.sample] = outcome.predicted_c2w
        for name, (records, row) in outcome.baselines.items():
            self.baseline_records.setdefault(name, []).extend(records)
            self.baseline_estimates.setdefault(name, []).append(row)

    def fail(self, task: EstimateTask, error: Exception | str) -> None:
        """Record an estimate that could not run on its views (none of its pairs is scored)."""
        self.failures.append({"sample": task.sample, "n": task.n, "views": list(task.views), "error": str(error)})


def evaluate_tasks(evaluation: Evaluation, estimator: ViewSetEstimator, tasks: Sequence[EstimateTask],
                   views: Mapping[int, ViewInput], unusable: Mapping[int, str] | None = None,
                   show_progress: bool = True, name: str = "evaluate",
                   on_estimate: Callable[[EstimateTask, EstimateOutcome], None] | None = None) -> Evaluation:
    """Run every task on its views (decoded once, shared by ID-Pose and the baselines), with a progress bar;
    ``on_estimate`` sees each estimate's outcome as it comes (for what the evaluation itself does not keep).

    An estimate whose views cannot be prepared (``PreprocessingError``: no plausible object in one of them)
    or that holds a view in ``unusable`` (view id -> why it could not be decoded) is recorded in
    ``failures`` and the run goes on; anything else the estimator raises ends the run.
    """
    unusable = unusable or {}
    with tqdm(total=len(tasks), desc="estimating", unit="set", file=sys.stderr, disable=not show_progress) as bar:
        for task in tasks:
            label = f"sample {task.sample}, {task.n} views"

            def progress(stage: str, done: int, total: int, label: str = label) -> None:
                text = f"{label}: {stage} {100 * done // max(total, 1)} %"
                if text != bar.postfix:
                    bar.set_postfix_str(text)

            bar.set_postfix_str(label)
            broken = [f"view {v}: {unusable[v]}" for v in task.views if v in unusable]
            try:
                if broken:
                    raise PreprocessingError("; ".join(broken))
                outcome = run_estimate(estimator, task, [views[v] for v in task.views], progress,
                                       evaluation.baselines)
                evaluation.add(task, outcome)
                if on_estimate is not None:
                    on_estimate(task, outcome)
            except PreprocessingError as err:  # one implausible view costs its estimate, not the run
                evaluation.fail(task, err)
                bar.write(f"{name}: {label}: not estimated: {err}", file=sys.stderr)
            bar.update()
    return evaluation
