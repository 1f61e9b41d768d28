#!/usr/bin/env python3
"""Accuracy of the embedded demo model, measured with ``evaluate_bag`` on bags no training run saw.

Renders fresh bags with ``make_synthetic_bag`` (camera seed ``--seed`` plus the object's index; training used
its own random cameras): one per demo object (held-out views of the training objects) and one per held-out
object (the first of the catalogue's benchmark objects, ``random_urdfs`` blobs the model never saw). Runs
``evaluate_bag`` offline on each (``--n 2``, ``--samples`` picks, the solver preset and model precision given),
and sums the pairs up per set beside the random-pose baseline that ``evaluate_bag`` scores on the same pairs. Prints
the table and writes bench/results/demo_model_accuracy/demo_model_accuracy.json (``_<precision>`` before ``.json``
unless float32).

    python bench/demo_model_accuracy.py [--samples 4] [--heldout 6] [--preset default] [--precision bfloat16]
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
from idpose_core.evaluation.estimator import ViewSetEstimator
from idpose_core.evaluation.protocol import EvaluationProtocol
from idpose_core.synthetic.catalogue import BENCH_HELDOUT, heldout_objects  # noqa: E402
from idpose_core.synthetic.scenes import demo_objects  # noqa: E402
from idpose_ros.dataset.synthetic_bag import SyntheticBagOptions, make_bag
from idpose_ros.evaluation.bag_evaluation import evaluate_bag
from idpose_ros.evaluation.bag_report import pooled_summaries, write_report  # noqa: E402
from idpose_ros.evaluation.estimators import EstimatorOptions, make_estimator

OUT = result_path("demo_model_accuracy")


def evaluate_set(object_set: str, names: list[str], estimator: ViewSetEstimator, args: argparse.Namespace,
                 work: Path) -> dict:
    """Make one bag per object, evaluate each; the pooled aggregates of the model and of random poses."""
    evaluations = []
    for index, name in enumerate(names):  # each bag its own cameras: one seed would repeat the relative poses
        bag = work / f"{object_set}_{name}"
        make_bag(bag, SyntheticBagOptions(object_set=object_set, object_name=name, views=args.views,
                                          seed=args.seed + index))
        evaluations.append(evaluate_bag(bag, estimator, protocol=EvaluationProtocol(args.samples, args.seed, (2,))))
        print(write_report(work / f"report_{object_set}_{name}", evaluations[-1]), flush=True)
    seconds = [estimate["seconds"] for evaluation in evaluations for estimate in evaluation.estimates]
    model, random = pooled_summaries(evaluations)
    return {"objects": names, "model": model, "random": random, "seconds_per_estimate": sum(seconds) / len(seconds)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=4, help="evaluate_bag picks per bag (one n = 2 pair each)")
    parser.add_argument("--views", type=int, default=12, help="views per bag")
    parser.add_argument("--heldout", type=int, default=6, help="held-out objects")
    parser.add_argument("--preset", choices=("default", "fast"), default="default")
    parser.add_argument("--seed", type=int, default=101, help="camera and pick seed of the fresh bags")
    parser.add_argument("--precision", choices=("float32", "bfloat16"), default="float32")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    if args.out is None:
        args.out = OUT if args.precision == "float32" else OUT.with_name(f"{OUT.stem}_{args.precision}.json")
    torch.set_num_threads(args.threads)
    started = time.monotonic()
    estimator = make_estimator(EstimatorOptions(preset=args.preset, precision=args.precision))
    with tempfile.TemporaryDirectory(prefix="idpose_demo_accuracy_") as folder:
        heldout_names = [spec.name for spec in heldout_objects(*BENCH_HELDOUT)]
        sets = {"demo objects, held-out views": evaluate_set("demo", [s.name for s in demo_objects()], estimator,
                                                            args, Path(folder)),
                "held-out objects": evaluate_set("heldout", heldout_names[:args.heldout], estimator, args,
                                                 Path(folder))}
    result = {"arguments": {k: str(v) for k, v in vars(args).items()}, "minutes": (time.monotonic() - started) / 60,
              "sets": sets}
    print("\n| set | pairs | RotAcc@15° | RotAcc@30° | mean rot. err. (°) | random RotAcc@15° | random RotAcc@30° "
          "| s / estimate |\n|---|---|---|---|---|---|---|---|")
    for name, row in sets.items():
        model, random = row["model"], row["random"]
        print(f"| {name} | {model['pairs']} | {100 * model['rot_acc_15']:.1f} | {100 * model['rot_acc_30']:.1f} | "
              f"{model['mean_rot_err_deg']:.1f} | {100 * random['rot_acc_15']:.1f} | {100 * random['rot_acc_30']:.1f} "
              f"| {row['seconds_per_estimate']:.1f} |")
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
