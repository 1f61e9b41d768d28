"""Predictor samples per estimate (ours, from the solver's counters) beside the official code's, n = 2..8.

Ours: ``estimate_poses`` run with the render oracle as a cheap predictor at the full iteration counts
of each preset; the counts do not depend on the predictor. Official: ``bench/official_counts.py``
(derived from its published algorithm). With ``bench/results/step_cost/step_cost.json`` present, both are
projected to full-size seconds on this CPU (``bench/unit_costs.py``), ours in each precision that run
measured: wall and CPU seconds of that run, and reference figures of a quiet machine
(``QUIET_REFERENCE``).

Usage (from the repository root): python -m bench.sample_counts [--views 2 4 6 8] [--presets default fast]
       [--precisions float32 bfloat16]
Writes bench/results/sample_counts/sample_counts.json.
"""
from __future__ import annotations

import argparse
import json
import time
from dataclasses import asdict

import torch

from bench.official_counts import OfficialSchedule, official_counts
from bench.result_files import result_path
from bench.solver_oracle import RENDER_SIZE, scene_cameras
from bench.unit_costs import all_costs
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
            "adjust_samples": result.stage_samples["exploration"][1], "oracle_stage_seconds": result.stage_seconds}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", nargs="+", type=int, default=[2, 4, 6, 8])
    parser.add_argument("--presets", nargs="+", default=["default", "fast"])
    parser.add_argument("--precisions", nargs="+", default=["float32", "bfloat16"],
                        help="our precisions to project (each must be in step_cost.json)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    try:
        costs = all_costs(args.precisions)
    except (FileNotFoundError, KeyError) as missing:
        costs = {}
        print(f"no projections: {missing}")

    rows = []
    for count in args.views:
        official = official_counts(count)
        row = {"n": count, "official": official, "ours": {}}
        if costs:
            official["projected"] = {measure: unit.official_seconds(official["probes"], official["steps"])
                                     for measure, unit in next(iter(costs.values())).items()}
        for preset in args.presets:
            start = time.perf_counter()
            ours = our_counts(count, preset)
            ours["projected"] = {
                precision: {measure: unit.ours_seconds(count, ours["forward_samples"], ours["backward_samples"],
                                                       ours["adjust_samples"]) for measure, unit in units.items()}
                for precision, units in costs.items()}
            row["ours"][preset] = ours
            print(f"n={count} {preset:<8} forward {ours['forward_samples']:>6} backward {ours['backward_samples']:>6}"
                  f" (adjust {ours['adjust_samples']})" + "".join(
                      f"  {precision}: {seconds['seconds'] / 60:.1f} min wall, "
                      f"{seconds['cpu_seconds'] / 60:.1f} min CPU"
                      for precision, seconds in ours["projected"].items())
                  + f"   (oracle run {time.perf_counter() - start:.1f} s)", flush=True)
        print(f"n={count} official forward {official['forward_samples']:>6} backward {official['backward_samples']:>6}"
              + (f"  {official['projected']['seconds'] / 60:.1f} min wall, "
                 f"{official['projected']['cpu_seconds'] / 60:.1f} min CPU" if costs else "")
              + f"   ({official['probes']} probes of {OfficialSchedule().probe_batch}, {official['steps']} steps)",
              flush=True)
        rows.append(row)

    report = {
        "presets": {preset: SolverConfig.preset(preset).as_dict() for preset in args.presets},
        "oracle_learning_rates": ORACLE_RATES,
        "official_schedule": asdict(OfficialSchedule()),
        "unit_costs": {precision: {measure: asdict(unit) for measure, unit in units.items()}
                       for precision, units in costs.items()} or None,
        "rows": rows,
    }
    out = result_path("sample_counts")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
