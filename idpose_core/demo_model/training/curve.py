"""``curve.csv``, the loss gaps and inversion checks against training minutes over a model's whole lineage, and
its plot."""
from __future__ import annotations

import csv
import shutil
from pathlib import Path

from matplotlib.figure import Figure

from idpose_core.demo_model.training.checks import ACCURACIES_DEG, CURVE_SETS, GAP_TIMESTEPS

CURVE_FILE = "curve.csv"
PLOT_FILE = "curve.png"


def curve_header() -> list[str]:
    """Columns of curve.csv: the loss, the gap per held-out set and timestep, the inversion checks per set."""
    return (["step", "minutes", "loss"] + [f"{name}_gap_t{t}" for name in CURVE_SETS for t in GAP_TIMESTEPS]
            + ["check_t"] + [f"{name}_acc{a}" for name in CURVE_SETS for a in ACCURACIES_DEG])


class Curve:
    """The work dir's curve.csv, appended to row by row; a work dir without one, started from a model folder, goes
    on with that folder's curve (the lineage's) where it stopped."""

    def __init__(self, work_dir: Path, init_from: Path | None):
        self.path = work_dir / CURVE_FILE
        if not self.path.is_file() and init_from is not None and (init_from / CURVE_FILE).is_file():
            shutil.copyfile(init_from / CURVE_FILE, self.path)
        new = not self.path.is_file()
        self._file = self.path.open("a", newline="")
        self._writer = csv.writer(self._file)
        if new:
            self._writer.writerow(curve_header())

    def write(self, step: int, minutes: float, loss: float, gaps: dict[str, dict[int, float]],
              check_t: int | None = None, checks: dict[str, dict[str, float]] | None = None) -> None:
        """One row: the mean loss since the last row, the loss gaps, and the inversion checks at ``check_t`` when
        they ran (empty cells otherwise)."""
        row_check = ([""] * (1 + len(CURVE_SETS) * len(ACCURACIES_DEG)) if checks is None
                     else [check_t] + [checks[name][f"acc{a}"] for name in CURVE_SETS for a in ACCURACIES_DEG])
        self._writer.writerow([step, round(minutes, 2), round(loss, 5)]
                              + [round(gaps[name][t], 4) for name in CURVE_SETS for t in GAP_TIMESTEPS] + row_check)
        self._file.flush()

    def publish(self, folder: Path) -> None:
        """Close the curve and put it, with its plot, into the model folder."""
        self._file.close()
        shutil.copyfile(self.path, folder / CURVE_FILE)
        plot_curve(self.path, folder / PLOT_FILE)


def plot_curve(curve_path: Path, png_path: Path) -> None:
    """``curve.csv`` as a PNG: the loss gap at each probe timestep and the inversion checks vs minutes, per held-out
    set (solid: novel objects, dashed: novel objects as a robot's crops, dotted: the demo objects)."""
    with curve_path.open() as handle:
        rows = list(csv.DictReader(handle))
    minutes = [float(row["minutes"]) for row in rows]
    figure = Figure(figsize=(11, 4))
    gap_axes, check_axes = figure.subplots(1, 2)
    for name, style in zip(CURVE_SETS, ("-", "--", ":")):
        for index, t in enumerate(GAP_TIMESTEPS):
            gap_axes.plot(minutes, [100 * float(row[f"{name}_gap_t{t}"]) for row in rows], style, color=f"C{index}",
                          label=f"{name}, t = {t}")
    gap_axes.set(xlabel="training minutes", ylabel="loss gap, wrong vs true pose (%)", title="held-out pairs")
    gap_axes.legend(fontsize="small")
    checks = [row for row in rows if row["check_t"]]
    for name, style in zip(CURVE_SETS, ("o-", "s--", "^:")):
        for index, accuracy in enumerate(ACCURACIES_DEG):
            check_axes.plot([float(row["minutes"]) for row in checks],
                            [100 * float(row[f"{name}_acc{accuracy}"]) for row in checks], style, color=f"C{index}",
                            label=f"{name}, RotAcc@{accuracy}")
    check_axes.set(xlabel="training minutes", ylabel="%", ylim=(0, 100),
                   title="grid-search inversion check (held-out pairs)")
    check_axes.legend(fontsize="small")
    figure.tight_layout()
    figure.savefig(png_path, dpi=100)
