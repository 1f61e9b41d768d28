"""The merged report of a data-set evaluation: report.json, report.md and errors.png in the output folder.

The per-estimate lines of results.jsonl are merged in plan order (not in the order they finished), so a
resumed run writes the report an uninterrupted one writes. Metrics per data set and n, as the paper's
Table 1, beside the random-pose baseline on the same pairs (``random_baseline``, seeded per estimate as
``evaluate_bag`` seeds it), the classical baselines that ran and, for flight recordings, the results the node
published (``LIVE_METHOD``), with the failed estimates counted and listed.
"""
from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after choosing the non-interactive backend)
import numpy as np  # noqa: E402

from idpose_core.baselines import TITLES  # noqa: E402
from idpose_core.evaluation.protocol import EstimateTask  # noqa: E402
from idpose_core.evaluation.scoring import RANDOM_DRAWS, random_baseline  # noqa: E402
from idpose_core.metrics import aggregate  # noqa: E402
from idpose_ros.dataset.inputs import DatasetInput  # noqa: E402
from idpose_ros.dataset.results import Key, task_key  # noqa: E402
from idpose_ros.evaluation.bag_report import RANDOM_METHOD, markdown_table, model_name, summary_table  # noqa: E402
from idpose_ros.evaluation.recording import LIVE_METHOD  # noqa: E402

ALL = "all data sets"


@dataclass
class DatasetEvaluation:
    """Every planned estimate's outcome: pair records and random-baseline records (each with its input and data
    set), the failed estimates, and per input what was planned."""

    about: dict[str, Any]  # model, node parameters, protocol, ground truth: what produced the numbers
    inputs: list[dict[str, Any]] = field(default_factory=list)
    records: list[dict[str, Any]] = field(default_factory=list)
    random_records: list[dict[str, Any]] = field(default_factory=list)
    failures: list[dict[str, Any]] = field(default_factory=list)
    missing: int = 0  # planned estimates without a line (an interrupted run)
    baseline_records: dict[str, list[dict[str, Any]]] = field(default_factory=dict)  # classical method -> pairs

    def datasets(self) -> list[str]:
        return list(dict.fromkeys(item["dataset"] for item in self.inputs))

    def scores(self, dataset: str | None = None, input_name: str | None = None) -> dict[str, Any] | None:
        """Aggregates of the model and of random poses over one data set, one input, or everything (None when no
        estimate there succeeded)."""
        def keep(record: dict[str, Any]) -> bool:
            return dataset in (None, record["dataset"]) and input_name in (None, record["input"])

        records = [record for record in self.records if keep(record)]
        if not records:
            return None
        return {"aggregates": aggregate(records),
                "random_baseline": {"guesses_per_pair": RANDOM_DRAWS,
                                    "aggregates": aggregate(r for r in self.random_records if keep(r))},
                "baselines": {name: aggregate(r for r in pairs if keep(r))
                              for name, pairs in self.baseline_records.items()}}


def merge(planned: Sequence[tuple[DatasetInput, Sequence[EstimateTask]]], lines: dict[Key, dict[str, Any]],
          about: dict[str, Any]) -> DatasetEvaluation:
    """The evaluation of the planned estimates from their latest results.jsonl lines, in plan order."""
    evaluation = DatasetEvaluation(about)
    for item, tasks in planned:
        done = failed = 0
        for task in tasks:
            line = lines.get(task_key(item.name, task))
            if line is None:
                evaluation.missing += 1
            elif line["status"] != "ok":
                failed += 1
                evaluation.failures.append({key: line[key] for key in ("input", "sample", "n", "views", "attempts",
                                                                        "error")})
            else:
                done += 1
                where = {"input": item.name, "dataset": item.dataset}
                evaluation.records += [{**where, **pair} for pair in line["pairs"]]
                evaluation.random_records += [{**where, **guess}
                                              for guess in random_baseline(task.true_c2w[:task.n], task.baseline_seed)]
                for name, baseline in line.get("baselines", {}).items():
                    evaluation.baseline_records.setdefault(name, []).extend(
                        {**where, **pair} for pair in baseline["pairs"])
        evaluation.inputs.append({"input": item.name, "kind": item.kind, "dataset": item.dataset,
                                  "views": item.summary(), "estimates": len(tasks), "succeeded": done,
                                  "failed": failed})
    return evaluation


def plot_errors(path: Path, evaluation: DatasetEvaluation) -> None:
    """Share of pairs under each rotation error, per data set (solid) and for random poses (dashed)."""
    figure, axes = plt.subplots(figsize=(7, 4.5))
    thresholds = np.linspace(0.0, 180.0, 361)
    for colour, dataset in zip(plt.cm.tab10.colors, evaluation.datasets()):
        for records, style, label in ((evaluation.records, "-", dataset),
                                      (evaluation.random_records, "--", f"{dataset}, {RANDOM_METHOD}")):
            errors = np.sort([r["rot_err_deg"] for r in records if r["dataset"] == dataset])
            if errors.size:
                axes.plot(thresholds, 100.0 * np.searchsorted(errors, thresholds) / errors.size, style,
                          color=colour, label=label)
    for threshold in (15, 30):
        axes.axvline(threshold, color="grey", linewidth=0.8, linestyle=":")
    axes.set(xlabel="rotation error (°)", ylabel="pairs below (%)", xlim=(0, 180), ylim=(0, 100),
             title="Rotation error per data set")
    axes.legend(fontsize=8, loc="lower right")
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


def write_dataset_report(out: Path, evaluation: DatasetEvaluation) -> str:
    """Write report.json, report.md and errors.png into ``out``; returns the markdown."""
    run, about = evaluation, evaluation.about
    method = f"ID-Pose ({about['node_parameters']['variant']})"
    datasets = {dataset: run.scores(dataset=dataset) for dataset in run.datasets()}
    overall = run.scores()
    counts = {"planned": sum(item["estimates"] for item in run.inputs),
              "succeeded": sum(item["succeeded"] for item in run.inputs), "failed": len(run.failures),
              "missing": run.missing}
    report = {**about, "estimates": counts, "datasets": datasets, "all": overall, "inputs": run.inputs,
              "failures": run.failures, "pairs": run.records}
    (out / "report.json").write_text(json.dumps(report, indent=2) + "\n")

    sections = []
    for dataset, scores in (*datasets.items(), *(((ALL, overall),) if len(datasets) > 1 else ())):
        inputs = [item for item in run.inputs if dataset in (ALL, item["dataset"])]
        failed = sum(item["failed"] for item in inputs)
        heading = (f"## {dataset}\n\n{len(inputs)} input{'s' if len(inputs) != 1 else ''}, "
                   f"{sum(item['succeeded'] for item in inputs)} estimates, {failed} failed.\n\n")
        sections.append(heading + (markdown_table({method: scores["aggregates"],
                                                   **{TITLES.get(name, name): aggregates
                                                      for name, aggregates in scores["baselines"].items()},
                                                   RANDOM_METHOD: scores["random_baseline"]["aggregates"]})
                                   if scores else "No estimate succeeded."))
    per_input = {f"{item['dataset']}/{Path(item['input']).name}": run.scores(input_name=item["input"])
                 for item in run.inputs}
    rows = {name: (scores["aggregates"]["all"], scores["random_baseline"]["aggregates"]["all"])
            for name, scores in per_input.items() if scores}
    failures = "".join(f"- `{f['input']}` sample {f['sample']}, n = {f['n']}, views {f['views']} "
                       f"({f['attempts']} attempts): {f['error']}\n" for f in run.failures)
    protocol = about["protocol"]
    recordings_note = (f"Flight recordings: each published result on its own views, estimated again and scored as "
                       f"the node published it (`{LIVE_METHOD}`). "
                       if any(item["kind"] == "recording" for item in run.inputs) else "")
    markdown = (
        "# Pose evaluation of a data set\n\n"
        f"{method}, mode {about['mode']}, model {model_name(about['model'])}, solver preset "
        f"{about['node_parameters']['solver_preset']}. Bags: {protocol['samples']} seeded pick(s) of up to 8 views "
        f"(seed {protocol['seed']}); official samples: their fixed views. Each is evaluated on its first "
        f"{', '.join(map(str, protocol['view_counts']))} views; the first view is the anchor. "
        + recordings_note +
        f"Estimates: {counts['planned']} planned, {counts['succeeded']} succeeded, {counts['failed']} failed "
        f"(after a retry)" + (f", {counts['missing']} not run yet" if counts["missing"] else "") + ".\n\n"
        + "\n\n".join(sections) + "\n\n"
        "Accuracies in %: rotation error below 15° / 30°, camera-centre error below 0.2 x the anchor's distance. "
        f"{RANDOM_METHOD}: each pair's target camera guessed uniformly on the sphere at the anchor's distance, "
        f"{RANDOM_DRAWS} guesses per pair (its pairs column counts guesses).\n\n"
        f"## Per input\n\n{summary_table(rows, label='input')}\n"
        + (f"\n## Failed estimates\n\n{failures}" if failures else ""))
    (out / "report.md").write_text(markdown)
    if run.records:
        plot_errors(out / "errors.png", run)
    return markdown
