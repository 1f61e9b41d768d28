"""Measured unit costs (``bench/results/step_cost/step_cost.json``) and full-size projections: counts x unit costs.

Ours, in one precision: a differentiated sample of a one-sample step (refinement, runner-up) costs
one measured step (``ours_step``); one of the exploration's adjust steps, which share batches of
``grad_batch``, costs the measured per-sample time of a solver adjust step (``ours_adjust``); every
forward-only sample costs a measured probe over its batch (``ours_probe`` of ``probe_samples``, the
solver's default probe batch, as the Zero-1-to-3 predictor runs per UNet call); each view is encoded once,
costed as one official per-step encode (VAE on two images + CLIP on one, so an upper bound for one view's VAE +
CLIP). Official (float32, as its
code runs): probes x ``official_probe`` + steps x ``official_step``. Medians of the step_cost run are
used, either wall seconds or process CPU seconds (these leave out time spent waiting for a core but
count threads spinning while they wait for each other; the encode share is scaled by the official
step's CPU/wall ratio); model loading is left out on both sides.
"""
from __future__ import annotations

import json
import statistics
from dataclasses import dataclass
from pathlib import Path

from bench.result_files import result_path

STEP_COST_FILE = result_path("step_cost")
MEASURES = ("seconds", "cpu_seconds")
# Reference figures of a quiet 2-core CPU of the kind measured here (2 threads): one official step (3.1 s of it
# re-encoding), one official probe, and a frozen float32 UNet step on cached conditioning (ours).
# ``reference_costs`` scales our other units from that step by measured CPU-time ratios.
QUIET_REFERENCE = {"official_step": 9.35, "official_probe": 86.6, "ours_step": 2.15, "encode": 3.1}
REFERENCE_PRECISION = "float32"


@dataclass(frozen=True)
class UnitCosts:
    """Seconds on this CPU for the full-size model (256 px, ``threads`` torch threads), ours in ``precision``."""

    ours_step: float
    ours_adjust_sample: float
    ours_probe: float
    probe_samples: int  # the noise samples of one measured probe
    official_step: float
    official_probe: float
    encode_per_view: float
    threads: int
    precision: str

    @classmethod
    def load(cls, path: Path = STEP_COST_FILE, measure: str = "seconds", precision: str = "float32") -> UnitCosts:
        """Medians of a ``bench/step_cost.py`` run in ``measure`` ("seconds" wall or "cpu_seconds").

        Raises FileNotFoundError naming the command that produces the file, KeyError naming a
        precision the run did not measure.
        """
        if measure not in MEASURES:
            raise ValueError(f"measure must be one of {MEASURES}, got {measure!r}")
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{path} is missing: run `python bench/step_cost.py` first (~12 GB, minutes)")
        report = json.loads(path.read_text())
        median = report["median"]
        if f"ours_step@{precision}" not in median:
            raise KeyError(f"{path} has no measurements in {precision}: "
                           f"rerun bench/step_cost.py --precisions {precision}")
        official_step = median["official_step"]
        encode_wall = statistics.median(run["parts"]["encode"] for run in report["runs"]["official_step"])
        adjust = median[f"ours_adjust@{precision}"]
        return cls(ours_step=median[f"ours_step@{precision}"][measure],
                   ours_adjust_sample=adjust["per_sample_seconds"] * adjust[measure] / adjust["seconds"],
                   ours_probe=median[f"ours_probe@{precision}"][measure],
                   probe_samples=int(report["setup"]["probe_batch"]), official_step=official_step[measure],
                   official_probe=median["official_probe"][measure],
                   encode_per_view=encode_wall * official_step[measure] / official_step["seconds"],
                   threads=int(report["machine"]["threads"]), precision=precision)

    def ours_seconds(self, views: int, forward_samples: int, backward_samples: int, adjust_samples: int) -> float:
        """Projected seconds of one estimate by this project's solver from its sample counters.

        ``adjust_samples``: the differentiated samples of the exploration's batched adjust steps
        (``SolverResult.stage_samples["exploration"][1]``); the other differentiated ones are one-sample steps.
        """
        forward_only = forward_samples - backward_samples
        return (views * self.encode_per_view + adjust_samples * self.ours_adjust_sample
                + (backward_samples - adjust_samples) * self.ours_step
                + forward_only * self.ours_probe / self.probe_samples)

    def official_seconds(self, probes: int, steps: int) -> float:
        """Projected seconds of one official estimate from its probe and step counts."""
        return probes * self.official_probe + steps * self.official_step


def reference_costs(measured_cpu: UnitCosts, measured_cpu_float32: UnitCosts) -> UnitCosts:
    """Unit costs from ``QUIET_REFERENCE``: our units = the reference float32 step x measured CPU-time ratios.

    ``measured_cpu`` holds our units in the wanted precision, ``measured_cpu_float32`` the float32 step
    they are scaled against (both CPU seconds of the same step_cost run).
    """
    reference = QUIET_REFERENCE
    scale = reference["ours_step"] / measured_cpu_float32.ours_step
    return UnitCosts(ours_step=measured_cpu.ours_step * scale,
                     ours_adjust_sample=measured_cpu.ours_adjust_sample * scale,
                     ours_probe=measured_cpu.ours_probe * scale, probe_samples=measured_cpu.probe_samples,
                     official_step=reference["official_step"], official_probe=reference["official_probe"],
                     encode_per_view=reference["encode"], threads=measured_cpu.threads,
                     precision=measured_cpu.precision)


def all_costs(precisions: list[str], path: Path = STEP_COST_FILE) -> dict[str, dict[str, UnitCosts]]:
    """precision -> {"seconds", "cpu_seconds", "reference_seconds"} -> UnitCosts, from one step_cost run."""
    float32_cpu = UnitCosts.load(path, "cpu_seconds", REFERENCE_PRECISION)
    costs = {}
    for precision in precisions:
        measured = {measure: UnitCosts.load(path, measure, precision) for measure in MEASURES}
        measured["reference_seconds"] = reference_costs(measured["cpu_seconds"], float32_cpu)
        costs[precision] = measured
    return costs
