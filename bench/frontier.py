#!/usr/bin/env python3
"""The accuracy-cost frontier of the solver's schedules: one table, one row per schedule.

Per row: predictor samples per estimate (the solver's counters on one render-oracle scene, no anchor
polar angle known, so 5 polar candidates, and the same scene with the elevation known, as gravity gives it),
seconds per estimate with the model of the bag rows (``--model``, default the embedded one), the projected
full-size seconds (``bench/unit_costs.py``, float32 and bfloat16), and RotAcc@15/30 and the median rotation
error on three sets: fresh bags (camera seed ``--seed``) of the held-out benchmark objects (``--object-set
heldout``, the default: objects the demo model never saw, where the presets face real ambiguity with a model
trained on many objects) or of the demo objects, the render oracle (``bench/solver_oracle.py``'s scenes, its
learning rates, no gravity) and rolled bags (up to 45 deg) estimated with their Imu gravity; the bags are
evaluated with ``evaluate_bag``; pair counts are distinct pairs. A preset made for gravity (``live``) skips
the fresh bags and scores its fallback's figures on the oracle (it runs that preset without gravity).
``--rows`` picks rows (``ROWS`` and the cost levers ``LEVERS``), ``--bag-rows`` those also run on the
bags; prints the table, writes bench/results/frontier/frontier.json (or ``--out``).

    python bench/frontier.py [--model training/novel_objects] [--objects 48] [--oracle-objects 12] [--rows fast live]
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

import numpy as np  # noqa: E402 (after the path setup)
import torch  # noqa: E402

from bench.result_files import result_path  # noqa: E402
from bench.solver_oracle import RENDER_SIZE, oracle_records, scene_cameras  # noqa: E402
from bench.unit_costs import UnitCosts  # noqa: E402
from idpose_core.evaluation.protocol import EvaluationProtocol  # noqa: E402
from idpose_core.metrics import aggregate  # noqa: E402
from idpose_core.model_loading import load_predictor  # noqa: E402
from idpose_core.solver import SolverConfig, SolverResult, estimate_poses  # noqa: E402
from idpose_core.synthetic.catalogue import BENCH_HELDOUT, heldout_objects  # noqa: E402
from idpose_core.synthetic.render_oracle import ORACLE_SOLVER_SETTINGS, RenderOracle  # noqa: E402
from idpose_core.synthetic.scenes import SceneRenderer, demo_objects, oracle_objects  # noqa: E402
from idpose_ros.dataset.synthetic_bag import IMU_TOPIC, SyntheticBagOptions, make_bag  # noqa: E402
from idpose_ros.evaluation.bag_evaluation import evaluate_bag  # noqa: E402
from idpose_ros.evaluation.bag_views import ExtraTopics  # noqa: E402
from idpose_ros.evaluation.estimators import EstimatorOptions, OfflineEstimator  # noqa: E402
from idpose_ros.evaluation.ground_truth import GroundTruthOptions  # noqa: E402

OUT = result_path("frontier")
# The fast preset before the frontier (kept to show what the leaner one saves).
OLD_FAST = dict(probe_batch=4, keep_top=3, refine_steps_per_view=100, runner_up_steps=30)
# row -> (view count, preset, SolverConfig overrides)
ROWS: dict[str, tuple[int, str, dict[str, Any]]] = {
    "default": (2, "default", {}),
    "fast (old)": (2, "default", OLD_FAST),
    "fast": (2, "fast", {}),
    "live": (2, "live", {}),
    "ifusion": (2, "ifusion", {}),
    "ifusion n=4": (4, "ifusion", {}),
}
# One lever at a time from the old fast schedule (n = 2), for choosing the new one, and from live.
LEVERS: dict[str, tuple[int, str, dict[str, Any]]] = {
    "old fast, probe 2": (2, "default", {**OLD_FAST, "probe_batch": 2}),
    "old fast, adjust 4": (2, "default", {**OLD_FAST, "adjust_top": 4}),
    "old fast, adjust 2": (2, "default", {**OLD_FAST, "adjust_top": 2}),
    "old fast, refine 50": (2, "default", {**OLD_FAST, "refine_steps_per_view": 50}),
    "old fast, stop 0.5 deg / 10": (2, "default", {**OLD_FAST, "refine_stop_deg": 0.5, "refine_stop_steps": 10}),
    "old fast, gate 0.3": (2, "default", {**OLD_FAST, "runner_up_gate": 0.3}),
    "old fast, 6 azimuths": (2, "default", {**OLD_FAST, "azimuth_candidates": 6}),
    "ifusion, 50 steps": (2, "ifusion", {"start_steps": 50}),
    "live, probe 2": (2, "live", {"probe_batch": 2}),
    "live, no narrowing": (2, "live", {"azimuth_refinements": 0}),
    "live, 8 azimuths, 3 narrowings": (2, "live", {"azimuth_candidates": 8, "azimuth_refinements": 3}),
    "live, refine 32": (2, "live", {"refine_steps_per_view": 32}),
    "live, no stop": (2, "live", {"refine_stop_steps": 0}),
    "live, no stop, refine 32": (2, "live", {"refine_stop_steps": 0, "refine_steps_per_view": 32}),
    "live, adjust best 2": (2, "live", {"adjust_steps": 10, "adjust_top": 2}),
}
ORACLE_RATES = {name: ORACLE_SOLVER_SETTINGS[name] for name in ("adjust_lr", "refine_lr")}
WITH_GRAVITY = GroundTruthOptions(extras=ExtraTopics(gravity_topic=IMU_TOPIC))
ROLL_DEG = 45.0


OBJECT_SETS = {"heldout": lambda: heldout_objects(*BENCH_HELDOUT), "demo": demo_objects}


def accuracy(records: list[dict]) -> dict[str, float]:
    """RotAcc@15/30 and median rotation error of pair records, with the number of distinct pairs (``bag`` names the
    bag of each record: the same views of two bags are two pairs)."""
    summary = aggregate(records)["all"]
    return {"pairs": summary["distinct_pairs"],
            **{key: summary[key] for key in ("rot_acc_15", "rot_acc_30", "median_rot_err_deg")}}


def bag_sets(rows: dict, args: argparse.Namespace, work: Path) -> dict[str, dict]:
    """Per row: its records on the fresh bags and the rolled bags with gravity, the cost of its fresh-bag estimates."""
    predictor = load_predictor(args.model, "cpu", "float32")
    out = {}
    bags = {}
    for index, spec in enumerate(OBJECT_SETS[args.object_set]()[: args.objects]):  # each bag its own cameras
        bags[("fresh", spec.name)] = make_bag(work / f"fresh_{spec.name}", SyntheticBagOptions(
            object_set=args.object_set, object_name=spec.name, views=args.views, seed=args.seed + 2 * index))
        bags[("rolled", spec.name)] = make_bag(work / f"rolled_{spec.name}", SyntheticBagOptions(
            object_set=args.object_set, object_name=spec.name, views=args.views, seed=args.seed + 2 * index + 1,
            roll_deg=ROLL_DEG))
    for row, (count, preset, overrides) in rows.items():
        estimator = OfflineEstimator(predictor, EstimatorOptions(preset=preset).node_values(),
                                     preset=preset, solver_overrides=overrides)
        protocol = EvaluationProtocol(args.pairs, args.seed, (count,))
        records: dict[str, list] = {"fresh": [], "rolled": []}
        estimates = []
        started = time.monotonic()
        for (kind, name), bag in bags.items():
            if kind not in args.bag_sets or (kind == "fresh" and SolverConfig.preset(preset).gravity_fallback):
                continue  # a set not asked for; or without gravity it runs its fallback, whose own row shows that
            evaluation = evaluate_bag(bag, estimator, WITH_GRAVITY if kind == "rolled" else None, protocol,
                                      show_progress=False)
            records[kind].extend({**record, "bag": name} for record in evaluation.records)
            estimates.extend({**estimate, "kind": kind} for estimate in evaluation.estimates)
        out[row] = {kind: accuracy(records[kind]) for kind in records if records[kind]}
        for kind in records:
            mine = [estimate for estimate in estimates if estimate["kind"] == kind]
            if mine:
                details = [estimate["details"] for estimate in mine]
                out[row][f"{kind}_samples"] = {
                    "forward_samples": float(np.mean([d["forward_samples"] for d in details])),
                    "backward_samples": float(np.mean([d["backward_samples"] for d in details])),
                    "batched_samples": float(np.mean([d["stage_samples"]["exploration"][1] for d in details]))}
                out[row][f"{kind}_seconds"] = float(np.mean([e["seconds"] for e in mine]))
        print(f"{row}: bags done in {time.monotonic() - started:.0f} s: {json.dumps(out[row])}", flush=True)
    return out


def oracle_set(rows: dict, args: argparse.Namespace) -> dict[str, dict]:
    """Per row: accuracy on the render oracle's scenes (its learning rates, the row's other settings) and the
    predictor samples of one of its estimates (the first scene; no anchor polar angle: 5 polar candidates), and of
    the same estimate with the view's elevation known (``gravity``: the azimuth search of a robot with an Imu)."""
    out = {}
    for row, (count, preset, overrides) in rows.items():
        config = SolverConfig.preset(preset, **{**overrides, **ORACLE_RATES})
        specs = oracle_objects()[: args.oracle_objects]
        records = oracle_records(specs, count, {row: config})[row]["records"]
        views = scene_cameras(0, 0, count)
        with SceneRenderer(specs[0], image_size=RENDER_SIZE) as renderer:
            renders = np.stack([renderer.render(*view)[0] for view in views])
        images = torch.from_numpy(renders).permute(0, 3, 1, 2).float() / 127.5 - 1.0
        oracle = RenderOracle(specs[0], views)
        out[row] = {"accuracy": accuracy(records), **counts(estimate_poses(oracle, images, config)),
                    "gravity": counts(estimate_poses(oracle, images, config, known_polar=views[1:, 0] - views[0, 0]))}
        print(f"{row}: oracle {json.dumps(out[row])}", flush=True)
    return out


def counts(result: SolverResult) -> dict[str, int]:
    """The predictor samples of one estimate that its projected cost needs."""
    return {"forward_samples": result.forward_samples, "backward_samples": result.backward_samples,
            "batched_samples": result.stage_samples["exploration"][1]}


def projected(row: dict, views: int) -> dict[str, float]:
    """Full-size seconds per estimate from the row's counters, float32 and bfloat16 (wall seconds of item 1)."""
    return {precision: UnitCosts.load(precision=precision).ours_seconds(
        views, row["forward_samples"], row["backward_samples"], row["batched_samples"])
        for precision in ("float32", "bfloat16")}


def table(result: dict) -> str:
    """The frontier as one Markdown table."""
    lines = ["| schedule | n | samples (differentiated) | full-size s float32 | full-size s bfloat16 "
             "| with gravity: samples (differentiated) | with gravity: full-size s bfloat16, oracle / rolled bags "
             "| bag model s, fresh / rolled | fresh bags @15 / @30 / median | oracle @15 / @30 / median "
             "| rolled + gravity @15 / @30 / median |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]

    def cell(acc: dict | None) -> str:
        if acc is None:
            return "not run"
        return (f"{100 * acc['rot_acc_15']:.0f}% / {100 * acc['rot_acc_30']:.0f}% / "
                f"{acc['median_rot_err_deg']:.2g} deg ({acc['pairs']})")

    def rolled(row: dict) -> str:
        return f"{row['projected_rolled']['bfloat16']:.0f}" if "projected_rolled" in row else "not run"

    def seconds(row: dict, kind: str) -> str:
        return f"{row[f'{kind}_seconds']:.1f}" if f"{kind}_seconds" in row else "not run"
    for name, row in result["rows"].items():
        gravity = row["gravity"]
        lines.append(f"| {name} | {row['n']} | {row['forward_samples']} ({row['backward_samples']}) | "
                     f"{row['projected']['float32']:.0f} | {row['projected']['bfloat16']:.0f} | "
                     f"{gravity['forward_samples']} ({gravity['backward_samples']}) | "
                     f"{row['projected_gravity']['bfloat16']:.0f} / {rolled(row)} | "
                     f"{seconds(row, 'fresh')} / {seconds(row, 'rolled')} | "
                     f"{cell(row.get('fresh'))} | {cell(row['oracle'])} | {cell(row.get('rolled'))} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rows", nargs="+", default=list(ROWS), choices=[*ROWS, *LEVERS])
    parser.add_argument("--bag-rows", nargs="*", help="rows also run on the bags (default: all of --rows)")
    parser.add_argument("--bag-sets", nargs="+", choices=("fresh", "rolled"), default=["fresh", "rolled"],
                        help="the bag sets to run (fresh: no gravity; rolled: with gravity)")
    parser.add_argument("--pairs", type=int, default=1, help="evaluate_bag picks per bag")
    parser.add_argument("--object-set", choices=tuple(OBJECT_SETS), default="heldout",
                        help="the objects of the fresh and rolled bags")
    parser.add_argument("--objects", type=int, default=48, help="objects (one fresh and one rolled bag each)")
    parser.add_argument("--views", type=int, default=8, help="views per bag")
    parser.add_argument("--oracle-objects", type=int, default=12, help="render-oracle objects (one scene each)")
    parser.add_argument("--seed", type=int, default=4242, help="camera and pick seed of the fresh bags")
    parser.add_argument("--model", default="", help="model folder of the bag rows (default: the embedded model)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    rows = {name: {**ROWS, **LEVERS}[name] for name in args.rows}
    started = time.monotonic()
    oracle = oracle_set(rows, args)
    bag_rows = {name: rows[name] for name in (args.rows if args.bag_rows is None else args.bag_rows)}
    with tempfile.TemporaryDirectory(prefix="idpose_frontier_") as folder:
        bags = bag_sets(bag_rows, args, Path(folder))
    result = {"arguments": {k: str(v) for k, v in vars(args).items() if k != "out"}, "rows": {}}
    for name, (count, preset, overrides) in rows.items():
        row = {"n": count, "preset": preset, "overrides": overrides, **bags.get(name, {}),
               **{key: value for key, value in oracle[name].items() if key != "accuracy"},
               "oracle": oracle[name]["accuracy"]}
        row["projected"] = projected(row, count)
        row["projected_gravity"] = projected(row["gravity"], count)
        if "rolled_samples" in row:
            row["projected_rolled"] = projected(row["rolled_samples"], count)
        result["rows"][name] = row
    result["minutes"] = (time.monotonic() - started) / 60
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print("\n" + table(result), flush=True)


if __name__ == "__main__":
    main()
