#!/usr/bin/env python3
"""The demo model on a robot's crops: poses on tabletop scenes with depth, under the training light and under
random lights, and on white, for one or more model folders side by side.

Renders fresh bags with ``make_synthetic_bag`` (seed ``--seed`` plus the object's index, never used in training):
per demo object a tabletop bag (textured table among 2-4 other objects, aligned 16UC1 depth and camera_info) lit
by the white scenes' light (``--light training``), the same scene lit by a random lamp with shadows
(``--light random``), and a white-background bag from fresh cameras. Runs ``evaluate_bag`` offline on each
(n = 2, ``--samples`` picks, ``--preset``; the tabletop bags with their depth and intrinsics, so the masks come
from depth) and sums the pairs up per set beside the random-pose baseline scored on the same pairs. Prints one
table and writes bench/results/robot_crops/robot_crops.json.

    python bench/robot_crops.py --model new=idpose_core/assets/demo_model --model old=/path/to/old_model
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

import torch  # noqa: E402 (after the path setup)

from bench.result_files import result_path  # noqa: E402
from idpose_core.evaluation.estimator import ViewSetEstimator  # noqa: E402
from idpose_core.evaluation.protocol import EvaluationProtocol  # noqa: E402
from idpose_core.synthetic.scenes import demo_objects  # noqa: E402
from idpose_ros.dataset.synthetic_bag import DEPTH_TOPIC, INFO_TOPIC, SyntheticBagOptions, make_bag  # noqa: E402
from idpose_ros.evaluation.bag_evaluation import evaluate_bag  # noqa: E402
from idpose_ros.evaluation.bag_report import pooled_summaries  # noqa: E402
from idpose_ros.evaluation.bag_views import ExtraTopics  # noqa: E402
from idpose_ros.evaluation.estimators import EstimatorOptions, make_estimator  # noqa: E402
from idpose_ros.evaluation.ground_truth import GroundTruthOptions  # noqa: E402

OUT = result_path("robot_crops")
DEPTH = GroundTruthOptions(extras=ExtraTopics(depth_topic=DEPTH_TOPIC, camera_info_topic=INFO_TOPIC))
SETS = {  # name -> (bag options besides object and seed, ground-truth options)
    "tabletop, depth, training light": ({"scene": "tabletop", "light": "training"}, DEPTH),
    "tabletop, depth, random light": ({"scene": "tabletop", "light": "random"}, DEPTH),
    "white background, fresh cameras": ({"scene": "plain"}, GroundTruthOptions()),
}


def make_bags(work: Path, views: int, seed: int) -> dict[str, list[Path]]:
    """Every set's bags, one per demo object, each its own cameras (seed ``seed`` plus the object's index: one seed
    for all would give every object the same relative poses)."""
    return {name: [make_bag(work / f"{index}_{spec.name}", SyntheticBagOptions(
        object_name=spec.name, views=views, seed=seed + number, **options))
        for number, spec in enumerate(demo_objects())]
        for index, (name, (options, _)) in enumerate(SETS.items())}


def evaluate_set(bags: list[Path], ground_truth: GroundTruthOptions, estimator: ViewSetEstimator,
                 protocol: EvaluationProtocol) -> dict:
    """The pooled aggregates of the model and of random poses over a set's bags (with the distinct pairs), and how
    many estimates failed on their views."""
    evaluations = [evaluate_bag(bag, estimator, ground_truth, protocol) for bag in bags]
    model, random = pooled_summaries(evaluations)
    seconds = [estimate["seconds"] for evaluation in evaluations for estimate in evaluation.estimates]
    return {"model": model, "random": random, "failed_estimates": sum(len(e.failures) for e in evaluations),
            "seconds_per_estimate": sum(seconds) / len(seconds)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", action="append", metavar="LABEL=PATH",
                        help="a model folder to measure, repeatable (default: the embedded demo model)")
    parser.add_argument("--samples", type=int, default=3, help="evaluate_bag picks per bag (one n = 2 pair each)")
    parser.add_argument("--views", type=int, default=12, help="views per bag")
    parser.add_argument("--preset", choices=("default", "fast"), default="fast")
    parser.add_argument("--seed", type=int, default=4242, help="scene, camera and pick seed of the fresh bags")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    models = dict(item.split("=", 1) for item in args.model or ["embedded="])
    torch.set_num_threads(args.threads)
    started = time.monotonic()
    protocol = EvaluationProtocol(args.samples, args.seed, (2,))
    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="idpose_robot_crops_") as folder:
        bags = make_bags(Path(folder), args.views, args.seed)
        for label, path in models.items():
            estimator = make_estimator(EstimatorOptions(model_path=path, preset=args.preset))
            results[label] = {}
            for name, (_, ground_truth) in SETS.items():
                results[label][name] = evaluate_set(bags[name], ground_truth, estimator, protocol)
                row = results[label][name]["model"]
                print(f"{label}, {name}: {row['pairs']} pairs, RotAcc@30 {100 * row['rot_acc_30']:.1f} %", flush=True)
    print("\n| model | set | pairs | RotAcc@15° | RotAcc@30° | mean rot. err. (°) | random RotAcc@30° | s / estimate |"
          "\n|---|---|---|---|---|---|---|---|")
    for label, sets in results.items():
        for name, row in sets.items():
            model, random = row["model"], row["random"]
            print(f"| {label} | {name} | {model['pairs']} | {100 * model['rot_acc_15']:.1f} | "
                  f"{100 * model['rot_acc_30']:.1f} | {model['mean_rot_err_deg']:.1f} | "
                  f"{100 * random['rot_acc_30']:.1f} | {row['seconds_per_estimate']:.1f} |")
    result = {"arguments": {k: str(v) for k, v in vars(args).items()}, "models": models,
              "minutes": (time.monotonic() - started) / 60, "results": results}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out} ({result['minutes']:.0f} min)")


if __name__ == "__main__":
    main()
