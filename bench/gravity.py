#!/usr/bin/env python3
"""What gravity buys: accuracy on rolled and upright cameras, and the predictor samples an estimate takes.

Renders fresh bags of the six demo objects with ``make_synthetic_bag`` (camera seed ``--seed``, never
used in training): once with every camera rolled by up to ``--roll-deg`` about its optical axis, once
upright (the same cameras otherwise). Each is evaluated with ``evaluate_bag`` (embedded demo model,
``--preset``, ``--n``) without gravity and with the bag's Imu (``/camera/imu``, mounted with
camera_link's axes: the extrinsic comes from the bag's transforms), the gravity polar angles kept
fixed or only used to start from (``known_polar``). Then one object under the
``default`` and ``fast`` presets, with and without gravity, for the solver's sample counters and the
seconds per estimate. Prints the tables and writes bench/results/gravity/gravity.json.

    python bench/gravity.py [--samples 2] [--roll-deg 45] [--preset fast] [--threads 2]
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

import numpy as np  # noqa: E402 (after the path setup)
import torch  # noqa: E402

from bench.result_files import result_path  # noqa: E402
from idpose_core.evaluation.protocol import EvaluationProtocol
from idpose_core.metrics import aggregate  # noqa: E402
from idpose_core.synthetic.scenes import demo_objects  # noqa: E402
from idpose_ros.dataset.synthetic_bag import IMU_TOPIC, SyntheticBagOptions, make_bag  # noqa: E402
from idpose_ros.evaluation.bag_evaluation import evaluate_bag
from idpose_ros.evaluation.bag_views import ExtraTopics  # noqa: E402
from idpose_ros.evaluation.estimators import EstimatorOptions, make_estimator
from idpose_ros.evaluation.ground_truth import GroundTruthOptions

OUT = result_path("gravity")
WITH_GRAVITY = GroundTruthOptions(extras=ExtraTopics(gravity_topic=IMU_TOPIC))
WITHOUT = GroundTruthOptions()
# (cameras, gravity) conditions of the accuracy runs: bag roll, ground-truth options, solver overrides
CONDITIONS = {"without gravity": (WITHOUT, ()), "with gravity": (WITH_GRAVITY, ()),
              "with gravity, polar refined": (WITH_GRAVITY, ("known_polar=start",))}


def cost(evaluations: list) -> dict[int, dict[str, float]]:
    """Per view count: mean predictor samples (evaluated, differentiated) and seconds per estimate."""
    rows: dict[int, list[dict]] = {}
    for evaluation in evaluations:
        for estimate in evaluation.estimates:
            rows.setdefault(estimate["n"], []).append(estimate)
    return {n: {"estimates": len(group),
                "forward_samples": float(np.mean([e["details"]["forward_samples"] for e in group])),
                "backward_samples": float(np.mean([e["details"]["backward_samples"] for e in group])),
                "exploration_samples": float(np.mean([e["details"]["stage_samples"]["exploration"][0]
                                                      for e in group])),
                "seconds": float(np.mean([e["seconds"] for e in group]))} for n, group in sorted(rows.items())}


def accuracy(args: argparse.Namespace, work: Path) -> dict:
    """Rolled and upright bags of every demo object, each evaluated without gravity and with it (polar angles
    kept); the rolled ones also with gravity's polar angles as a start only (refinement moves them)."""
    estimators = {overrides: make_estimator(EstimatorOptions(preset=args.preset, solver_params=overrides))
                  for _, overrides in CONDITIONS.values()}
    protocol = EvaluationProtocol(args.samples, args.seed, tuple(args.n))
    runs: dict[str, list] = {}
    for spec in demo_objects():
        for cameras, roll in (("rolled", args.roll_deg), ("upright", 0.0)):
            bag = make_bag(work / f"{cameras}_{spec.name}", SyntheticBagOptions(
                object_name=spec.name, views=args.views, seed=args.seed, roll_deg=roll))
            for gravity, (options, overrides) in CONDITIONS.items():
                if overrides and cameras == "upright":
                    continue  # the polar angles' fixed-vs-refined question is asked on the rolled cameras
                print(f"{spec.name}, {cameras} cameras, {gravity}", flush=True)
                runs.setdefault(f"{cameras}, {gravity}", []).append(
                    evaluate_bag(bag, estimators[overrides], options, protocol))
    return {name: {"aggregates": aggregate([r for e in evaluations for r in e.records]),
                   "random": aggregate([r for e in evaluations for r in e.random_records]),
                   "cost": cost(evaluations)} for name, evaluations in runs.items()}


def presets(args: argparse.Namespace, work: Path) -> dict:
    """One rolled bag (the first demo object), one pick, both presets, with and without gravity: the cost."""
    bag = make_bag(work / "presets", SyntheticBagOptions(object_name=demo_objects()[0].name, views=args.views,
                                                         seed=args.seed, roll_deg=args.roll_deg))
    protocol = EvaluationProtocol(1, args.seed, tuple(args.n))
    result = {}
    for preset in ("default", "fast"):
        estimator = make_estimator(EstimatorOptions(preset=preset))
        for gravity, options in (("without gravity", WITHOUT), ("with gravity", WITH_GRAVITY)):
            print(f"cost: {preset}, {gravity}", flush=True)
            result[f"{preset}, {gravity}"] = cost([evaluate_bag(bag, estimator, options, protocol)])
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=1, help="evaluate_bag picks per bag")
    parser.add_argument("--views", type=int, default=12, help="views per bag")
    parser.add_argument("--n", type=int, nargs="+", default=[2, 4], help="view counts")
    parser.add_argument("--roll-deg", type=float, default=45.0, help="largest camera roll of the rolled bags")
    parser.add_argument("--preset", choices=("default", "fast"), default="fast", help="preset of the accuracy runs")
    parser.add_argument("--seed", type=int, default=202, help="camera, roll and pick seed of the fresh bags")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--skip-presets", action="store_true", help="accuracy only")
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="idpose_gravity_") as folder:
        result = {"arguments": {k: str(v) for k, v in vars(args).items() if k != "out"},
                  "accuracy": accuracy(args, Path(folder))}
        if not args.skip_presets:
            result["cost"] = presets(args, Path(folder))
    result["minutes"] = (time.monotonic() - started) / 60
    print("\n| cameras, gravity | n | pairs | RotAcc@15° | RotAcc@30° | mean rot. err. (°) | random RotAcc@30° "
          "| samples / estimate | s / estimate |\n|---|---|---|---|---|---|---|---|---|")
    for name, row in result["accuracy"].items():
        for n, cost_row in row["cost"].items():
            model, random = row["aggregates"][str(n)], row["random"][str(n)]
            print(f"| {name} | {n} | {model['pairs']} | {100 * model['rot_acc_15']:.1f} | "
                  f"{100 * model['rot_acc_30']:.1f} | {model['mean_rot_err_deg']:.1f} | "
                  f"{100 * random['rot_acc_30']:.1f} | {cost_row['forward_samples']:.0f} | {cost_row['seconds']:.1f} |")
    if "cost" in result:
        print("\n| preset, gravity | n | samples evaluated | of which exploration | differentiated | s / estimate |"
              "\n|---|---|---|---|---|---|")
        for name, rows in result["cost"].items():
            for n, row in rows.items():
                print(f"| {name} | {n} | {row['forward_samples']:.0f} | {row['exploration_samples']:.0f} | "
                      f"{row['backward_samples']:.0f} | {row['seconds']:.1f} |")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out} ({result['minutes']:.0f} min)")


if __name__ == "__main__":
    main()
