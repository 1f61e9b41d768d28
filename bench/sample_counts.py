"""Predictor samples per estimate (ours, from the solver's counters) beside the official code's, n = 2..8.

Ours: ``estimate_poses`` run with the render oracle as a cheap predictor at the full iteration counts
of each preset; the counts do not depend on the predictor. Official: ``bench/official_counts.py``
(derived from its published algorithm). With ``bench/results/step_cost.json`` present, both are
projected to full-size seconds on this CPU (``bench/unit_costs.py``): wall and CPU seconds of that
run, and the issue's quiet-machine reference figures (``ISSUE_REFERENCE``).

Usage (from the repository root): python -m bench.sample_counts [--views 2 4 6 8] [--presets default fast]
Writes bench/results/sample_counts.json.
"""
from __future__ import annotations

import argparse
import json
import time
from dataclasses import asdict

import torch

from bench.official_counts import OfficialSchedule, official_counts
from bench.solver_oracle import RENDER_SIZE, scene_cameras
from bench.unit_costs import MEASURES, RESULTS, UnitCosts, reference_costs
from idpose_core.solver import SolverConfig, estimate_poses
from idpose_core.synthetic.render_oracle import ORACLE_SOLVER_SETTINGS, RenderOracle
from idpose_core.synthetic.scenes import oracle_objects

ORACLE_RATES = {key: ORACLE_SOLVER_SETTINGS[key] for key in ("adjust_lr", "refine_lr")}


def our_counts(count: int, preset: str) -> dict:
    """Sample counters and stage seconds of one oracle estimate of ``count`` views under ``preset``."""
    views = scene_cameras(0, 0, count)
    oracle = RenderOracle(oracle_objects()[0], views)
    images = torch.zeros(count, 3, RENDER_SIZE, RENDER_SIZE)
    result = estimate_poses(oracle, images, SolverConfig.preset(preset, **ORACLE_RATES))
    return {"forward_samples": result.forward_samples, "backward_samples": result.backward_samples,
            "oracle_stage_seconds": result.stage_seconds}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", nargs="+", type=int, default=[2, 4, 6, 8])
    parser.add_argument("--presets", nargs="+", default=["default", "fast"])
    args = parser.parse_args()
    torch.set_num_threads(1)
    try:
        costs = {measure: UnitCosts.load(measure=measure) for measure in MEASURES}
        costs["reference_seconds"] = reference_costs(costs["cpu_seconds"])
    except FileNotFoundError as missing:
        costs = {}
        print(f"no projections: {missing}")

    rows = []
    for count in args.views:
        official = official_counts(count)
        row = {"n": count, "official": official, "ours": {}}
        for measure, unit in costs.items():
            official[f"projected_{measure}"] = unit.official_seconds(official["probes"], official["steps"])
        for preset in args.presets:
            start = time.perf_counter()
            ours = our_counts(count, preset)
            for measure, unit in costs.items():
                ours[f"projected_{measure}"] = unit.ours_seconds(count, ours["forward_samples"], ours["backward_samples"])
            row["ours"][preset] = ours
            print(f"n={count} {preset:<8} forward {ours['forward_samples']:>6} backward {ours['backward_samples']:>6}"
                  + (f"  projected {ours['projected_seconds'] / 60:7.1f} min wall, "
                     f"{ours['projected_cpu_seconds'] / 60:7.1f} min CPU" if costs else "")
                  + f"   (oracle run {time.perf_counter() - start:.1f} s)", flush=True)
        print(f"n={count} official forward {official['forward_samples']:>6} backward {official['backward_samples']:>6}"
              + (f"  projected {official['projected_seconds'] / 60:7.1f} min wall, "
                 f"{official['projected_cpu_seconds'] / 60:7.1f} min CPU" if costs else "")
              + f"   ({official['probes']} probes of {OfficialSchedule().probe_batch}, {official['steps']} steps)",
              flush=True)
        rows.append(row)

    report = {
        "presets": {preset: SolverConfig.preset(preset).as_dict() for preset in args.presets},
        "oracle_learning_rates": ORACLE_RATES,
        "official_schedule": asdict(OfficialSchedule()),
        "unit_costs": {measure: asdict(unit) for measure, unit in costs.items()} or None,
        "rows": rows,
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    out = RESULTS / "sample_counts.json"
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
