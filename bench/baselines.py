#!/usr/bin/env python3
"""ID-Pose beside the classical baselines (COLMAP, SIFT + essential matrix) and random poses, on the same views.

Two sets: the six shipped demo bags (``data/demo_bags/<object>``) and fresh bags of the textured objects
(``make_synthetic_bag --objects textured``, 12 views, camera seed ``--seed``, ``--size`` px: detailed textures
and enough pixels for SIFT). ``evaluate_bag`` runs offline on each with ``--baselines colmap features`` (the
embedded demo model, ``--preset``, n = 2 and 4, ``--samples`` picks) and writes its report into
``--work-dir/<bag>/``; a bag whose report is there already is not evaluated again, so an interrupted run
resumes. The pairs and estimates of each set are pooled from the reports per method and view count:
RotAcc@15/30, mean rotation error, the convergence counts "A + B of C", seconds per estimate, and RotAcc@15
by the true angle between anchor and target. The baselines cost seconds, ID-Pose minutes, so the baselines
alone also run on ``--baseline-samples`` picks per bag (the same tasks ``evaluate_bag`` plans, through its
``classical_baseline``), for convergence counts and accuracy by angle on more pairs. Prints the tables and
writes bench/results/baselines/baselines.json. ``--jobs`` bags are evaluated at once, each in its own process with its
own model and ``--threads`` threads.

    python bench/baselines.py [--samples 1] [--preset fast] [--size 512] [--jobs 2 --threads 1]
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

import numpy as np  # noqa: E402 (after the path setup)
import torch  # noqa: E402

from bench.result_files import result_path  # noqa: E402
from idpose_core.baselines import BASELINES, TITLES  # noqa: E402
from idpose_core.baselines.scoring import estimate_summary  # noqa: E402
from idpose_core.evaluation.estimator import ViewSetEstimator
from idpose_core.evaluation.protocol import EvaluationProtocol
from idpose_core.evaluation.run import classical_baseline
from idpose_core.metrics import aggregate  # noqa: E402
from idpose_core.synthetic.scenes import textured_objects  # noqa: E402
from idpose_ros.dataset.synthetic_bag import SyntheticBagOptions, make_bag
from idpose_ros.evaluation.bag_evaluation import evaluate_bag, plan_bag
from idpose_ros.evaluation.bag_report import RANDOM_METHOD, write_report  # noqa: E402
from idpose_ros.evaluation.bag_views import load_views
from idpose_ros.evaluation.demo_run import demo_bags
from idpose_ros.evaluation.estimators import EstimatorOptions, make_estimator
from idpose_ros.evaluation.ground_truth import GroundTruthOptions, read_views

OUT = result_path("baselines")
ID_POSE = "ID-Pose (demo model)"
ANGLE_BINS = ((0.0, 30.0), (30.0, 60.0), (60.0, 180.0))  # true anchor-target angle, degrees
_WORKER: dict[str, ViewSetEstimator] = {}  # the model of this worker process


def start_worker(preset: str, threads: int) -> None:
    """Load the embedded demo model once per worker process."""
    torch.set_num_threads(threads)
    _WORKER["estimator"] = make_estimator(EstimatorOptions(preset=preset))


def evaluate(bag: Path, samples: int, report: Path) -> Path:
    """ID-Pose and every baseline on the bag's n = 2 and 4 estimates, written to ``report``."""
    evaluation = evaluate_bag(bag, _WORKER["estimator"], protocol=EvaluationProtocol(samples, 0, (2, 4)),
                              show_progress=False, baselines=tuple(BASELINES))
    write_report(report, evaluation)
    print(f"{bag.name} done", flush=True)
    return report / "report.json"


def separation_deg(pair: dict, anchor_polar_deg: float) -> float:
    """Angle (degrees) between the anchor's and the target's directions from the object centre."""
    d_polar, d_azimuth, _ = pair["true_rel_sph"]
    polar = math.radians(anchor_polar_deg)
    cosine = math.cos(polar) * math.cos(polar + d_polar) + math.sin(polar) * math.sin(polar + d_polar) * math.cos(
        d_azimuth)
    return math.degrees(math.acos(min(max(cosine, -1.0), 1.0)))


def baselines_only(bag: Path, samples: int) -> dict:
    """A report-like dict of the baselines alone on ``samples`` picks of the bag (n = 2 and 4)."""
    ground_truth = GroundTruthOptions()
    views = read_views(bag, ground_truth)
    tasks = plan_bag(views, ground_truth, EvaluationProtocol(samples, 0, (2, 4)))
    decoded, _ = load_views(bag, ground_truth.image_topic, {v for task in tasks for v in task.pick}, views,
                            ground_truth.inputs)
    report: dict = {"bag": str(bag), "estimates": [], "baselines": {}}
    for name in BASELINES:
        outcomes = [classical_baseline(name, task, [decoded[v] for v in task.views]) for task in tasks]
        report["baselines"][name] = {"pairs": [p for records, _ in outcomes for p in records],
                                     "estimates": [row for _, row in outcomes]}
    for task in tasks:  # the anchor's polar angle, for the angle between views
        report["estimates"].append({"sample": task.sample, "n": task.n, "anchor_polar_deg": float(np.degrees(
            np.arccos(np.clip(task.true_c2w[0, 2, 3] / np.linalg.norm(task.true_c2w[0, :3, 3]), -1.0, 1.0))))})
    return report


def pooled(reports: list[dict]) -> dict:
    """Per method: aggregates of all pairs, estimate summaries and RotAcc@15 per angle bin; random poses."""
    methods = {ID_POSE: ([(r, p) for r in reports for p in r["pairs"]], [e for r in reports for e in r["estimates"]])
               } if "pairs" in reports[0] else {}
    for name in BASELINES:
        methods[TITLES[name]] = ([(r, p) for r in reports for p in r["baselines"][name]["pairs"]],
                                 [e for r in reports for e in r["baselines"][name]["estimates"]])
    result = {}
    for method, (pairs, rows) in methods.items():
        polar = {(r["bag"], e["sample"], e["n"]): e["anchor_polar_deg"] for r in reports for e in r["estimates"]}
        angles = np.array([separation_deg(p, polar[(r["bag"], p["sample"], p["n"])]) for r, p in pairs])
        errors = np.array([p["rot_err_deg"] for _, p in pairs])
        by_angle = {}
        for low, high in ANGLE_BINS:
            inside = (angles >= low) & (angles < high)
            accuracy = float(np.mean(errors[inside] < 15)) if inside.any() else None
            by_angle[f"{low:g}-{high:g}"] = {"pairs": int(np.sum(inside)), "rot_acc_15": accuracy}
        result[method] = {"aggregates": aggregate([p for _, p in pairs]), "estimates": estimate_summary(rows),
                          "rot_acc_15_by_angle": by_angle}
    if "random_baseline" not in reports[0]:
        return result
    random = [r["random_baseline"]["aggregates"] for r in reports]
    result[RANDOM_METHOD] = {"aggregates": {group: {
        "pairs": sum(a[group]["pairs"] for a in random),
        **{key: sum(a[group][key] * a[group]["pairs"] for a in random) / sum(a[group]["pairs"] for a in random)
           for key in ("rot_acc_15", "rot_acc_30", "mean_rot_err_deg")}} for group in random[0]}}
    return result


def print_set(name: str, methods: dict) -> None:
    print(f"\n{name}\n\n| method | views | RotAcc@15° | RotAcc@30° | mean rot. err. (°) | pairs "
          "| converged (A + B of C) | s / estimate |\n|---|---|---|---|---|---|---|---|")
    for method, row in methods.items():
        for group, summary in row["aggregates"].items():
            estimates = row.get("estimates", {}).get(group)
            counts = (f"{estimates['converged']} + {estimates['fewer']} of {estimates['estimates']}"
                      if estimates and "converged" in estimates else "—")
            seconds = f"{estimates['mean_seconds']:.2f}" if estimates else "—"
            print(f"| {method} | {group} | {100 * summary['rot_acc_15']:.1f} | {100 * summary['rot_acc_30']:.1f} | "
                  f"{summary['mean_rot_err_deg']:.1f} | {summary['pairs']} | {counts} | {seconds} |")
    print("\n| method | " + " | ".join(f"RotAcc@15°, {low:g}-{high:g}° apart (pairs)" for low, high in ANGLE_BINS)
          + " |\n|---|---|---|---|")
    for method, row in methods.items():
        if "rot_acc_15_by_angle" in row:
            cells = [f"{100 * b['rot_acc_15']:.1f} ({b['pairs']})" if b["rot_acc_15"] is not None
                     else f"— ({b['pairs']})" for b in row["rot_acc_15_by_angle"].values()]
            print(f"| {method} | " + " | ".join(cells) + " |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=1, help="evaluate_bag picks per bag (n = 2 and 4 each)")
    parser.add_argument("--preset", choices=("default", "fast"), default="fast")
    parser.add_argument("--seed", type=int, default=101, help="camera seed of the fresh textured bags")
    parser.add_argument("--size", type=int, default=512, help="image size of the fresh textured bags (px)")
    parser.add_argument("--baseline-samples", type=int, default=10, help="picks per bag for the baselines alone")
    parser.add_argument("--jobs", type=int, default=2, help="bags evaluated at once")
    parser.add_argument("--threads", type=int, default=1, help="torch threads per job")
    parser.add_argument("--work-dir", type=Path, default=Path.home() / ".cache" / "idpose_bench_baselines",
                        help="textured bags and every bag's report (kept: a rerun resumes)")
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    started = time.monotonic()
    bags = {"demo bags": demo_bags(), "textured objects": []}
    for spec in textured_objects():
        bag = args.work_dir / "bags" / spec.name
        if not bag.exists():
            make_bag(bag, SyntheticBagOptions(object_set="textured", object_name=spec.name, views=12, seed=args.seed,
                                              size=args.size))
        bags["textured objects"].append(bag)
    reports = {name: [args.work_dir / "reports" / bag.name for bag in paths] for name, paths in bags.items()}
    todo = [(bag, report) for name in bags for bag, report in zip(bags[name], reports[name])
            if not (report / "report.json").is_file()]
    with ProcessPoolExecutor(args.jobs, initializer=start_worker, initargs=(args.preset, args.threads)) as pool:
        for done in [pool.submit(evaluate, bag, args.samples, report) for bag, report in todo]:
            done.result()
    sets = {name: {"bags": [bag.name for bag in bags[name]],
                   "methods": pooled([json.loads((report / "report.json").read_text()) for report in reports[name]])}
            for name in bags}
    for name, paths in bags.items():
        sets[name]["baselines_only"] = pooled([baselines_only(bag, args.baseline_samples) for bag in paths])
    for name, result in sets.items():
        print_set(name, result["methods"])
        print_set(f"{name}, the baselines alone on {args.baseline_samples} picks per bag", result["baselines_only"])
    args.out.write_text(json.dumps({"arguments": {k: str(v) for k, v in vars(args).items()},
                                    "minutes": (time.monotonic() - started) / 60, "sets": sets}, indent=2) + "\n")
    print(f"\nwrote {args.out}")


if __name__ == "__main__":
    main()
