"""results.jsonl: one JSON line per finished estimate, appended as it finishes, so that a rerun resumes.

Beside it, run.json keeps the settings the lines were made with (model, node parameters, ground truth,
seed); a rerun into the same folder must use the same ones. A line is final once written (flushed and
synced): a crash loses at most the estimates in flight and, torn mid-write, the last line, which the
next run drops. The latest line of an estimate counts; a rerun skips the estimates that succeeded and
tries the failed ones again.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from idpose_core.evaluation.protocol import EstimateTask
from idpose_ros.dataset.inputs import DatasetInput
from idpose_ros.dataset.ray_runner import JobResult

RESULTS_FILE = "results.jsonl"
SETTINGS_FILE = "run.json"
Key = tuple[str, int, int, tuple[int, ...]]


class SettingsMismatch(ValueError):
    """The output folder holds results made with other settings."""


def task_key(input_name: str, task: EstimateTask) -> Key:
    """What identifies an estimate across runs: the input, the sample, n and the views."""
    return input_name, task.sample, task.n, tuple(task.pick[:task.n])


def line_key(line: dict[str, Any]) -> Key:
    return line["input"], line["sample"], line["n"], tuple(line["views"])


def result_line(item: DatasetInput, result: JobResult, solver_seed: int) -> dict[str, Any]:
    """The results.jsonl line of a finished estimate: which one, its seeds, and its poses and errors or its error;
    the classical baselines' and the input's own answers (a recording's published result) beside them."""
    task = result.task
    line = {"input": item.name, "dataset": item.dataset, "kind": item.kind, "sample": task.sample, "n": task.n,
            "views": list(task.pick[:task.n]), "status": "failed" if result.outcome is None else "ok",
            "attempts": result.attempts,
            "seeds": {"protocol": task.seed, "solver": solver_seed, "random_baseline": list(task.baseline_seed)}}
    if result.outcome is None:
        return {**line, "error": result.error}
    row = result.outcome.row
    return {**line, "worker": result.worker, "seconds": row["seconds"], "anchor_polar_deg": row["anchor_polar_deg"],
            "object_distance": row["object_distance"], "true_c2w": task.true_c2w[:task.n].tolist(),
            "predicted_c2w": result.outcome.predicted_c2w.tolist(), "pairs": result.outcome.records,
            "baselines": {name: {"pairs": records, "row": baseline_row}
                          for name, (records, baseline_row) in {**result.outcome.baselines,
                                                                 **item.published(task)}.items()}}


class ResultsLog:
    """results.jsonl and run.json of an output folder: what is finished, and appending as estimates finish."""

    def __init__(self, out: Path, settings: dict[str, Any]):
        """SettingsMismatch when the folder holds results of other settings (settings without results are replaced:
        a run that stopped before its first estimate, e.g. on a wrong model path, binds nothing)."""
        out.mkdir(parents=True, exist_ok=True)
        settings = json.loads(json.dumps(settings))
        self.path, settings_path = out / RESULTS_FILE, out / SETTINGS_FILE
        self.lines: dict[Key, dict[str, Any]] = self._read()
        if self.lines and settings_path.exists():
            previous = json.loads(settings_path.read_text())
            changed = sorted(key for key in {*previous, *settings} if previous.get(key) != settings.get(key))
            if changed:
                raise SettingsMismatch(f"{out} holds results made with other {', '.join(changed)} ({settings_path}); "
                                       "choose another --out, or rerun with the same settings to resume")
        settings_path.write_text(json.dumps(settings, indent=2) + "\n")
        self._file = self.path.open("a")

    def _read(self) -> dict[Key, dict[str, Any]]:
        """The latest line per estimate; a last line torn by a crash is cut off the file."""
        if not self.path.exists():
            return {}
        data = self.path.read_bytes()
        if data and not data.endswith(b"\n"):
            data = data[:data.rfind(b"\n") + 1]
            with self.path.open("r+b") as file:
                file.truncate(len(data))
        lines = (json.loads(text) for text in data.decode().splitlines() if text.strip())
        return {line_key(line): line for line in lines}

    def done(self, key: Key) -> bool:
        """Whether the estimate has succeeded in this or an earlier run."""
        return self.lines.get(key, {}).get("status") == "ok"

    def append(self, line: dict[str, Any]) -> None:
        self._file.write(json.dumps(line) + "\n")
        self._file.flush()
        os.fsync(self._file.fileno())
        self.lines[line_key(line)] = line

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> ResultsLog:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
