#!/usr/bin/env python3
"""The embedded model on objects it never saw, and on its six demo objects, for one or more model folders.

Renders fresh bags with ``make_synthetic_bag`` (seed ``--seed``, never used in training): one per held-out
benchmark object (``idpose_core.synthetic.catalogue.BENCH_HELDOUT``: ``random_urdfs`` blobs 850-873 and 24
held-out toys; no training run and no training curve saw them) on white and on a tabletop among other objects
with aligned depth under a random lamp, and one per demo object on white and on a tabletop. Runs
``evaluate_bag`` offline on each (n = 2, ``--preset``; on white without and with gravity from the bag's Imu;
tabletops with their depth and intrinsics, so the masks come from depth) and sums the pairs up per set beside
the random-pose baseline scored on the same pairs, counting distinct pairs. Every model given runs on the same
bags. Prints one table and writes bench/results/novel_objects/novel_objects.json, keeping the rows of models not
run this time when the bags were the same.

    python bench/novel_objects.py --model new=idpose_core/assets/demo_model --model old=/path/to/old_model
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
from bench.robot_crops import evaluate_set  # noqa: E402
from idpose_core.evaluation.protocol import EvaluationProtocol  # noqa: E402
from idpose_core.synthetic.catalogue import BENCH_HELDOUT, heldout_objects  # noqa: E402
from idpose_core.synthetic.scenes import demo_objects  # noqa: E402
from idpose_ros.dataset.synthetic_bag import (  # noqa: E402
    DEPTH_TOPIC,
    IMU_TOPIC,
    INFO_TOPIC,
    SyntheticBagOptions,
    make_bag,
)
from idpose_ros.evaluation.bag_views import ExtraTopics  # noqa: E402
from idpose_ros.evaluation.estimators import EstimatorOptions, make_estimator  # noqa: E402
from idpose_ros.evaluation.ground_truth import GroundTruthOptions  # noqa: E402

OUT = result_path("novel_objects")
PLAIN, GRAVITY = GroundTruthOptions(), GroundTruthOptions(extras=ExtraTopics(gravity_topic=IMU_TOPIC))
DEPTH = GroundTruthOptions(extras=ExtraTopics(depth_topic=DEPTH_TOPIC, camera_info_topic=INFO_TOPIC))
WHITE, TABLETOP = {"scene": "plain"}, {"scene": "tabletop", "light": "random"}
SETS = {  # name -> (object set, scene options, ground-truth options, picks per bag)
    "held-out objects, white": ("heldout", WHITE, PLAIN, "heldout_samples"),
    "held-out objects, white, elevation known": ("heldout", WHITE, GRAVITY, "heldout_samples"),
    "held-out objects, tabletop, depth, random light": ("heldout", TABLETOP, DEPTH, "heldout_samples"),
    "demo objects, white, fresh cameras": ("demo", WHITE, PLAIN, "demo_samples"),
    "demo objects, tabletop, depth, random light": ("demo", TABLETOP, DEPTH, "demo_samples"),
}
OBJECTS = {"heldout": lambda: heldout_objects(*BENCH_HELDOUT), "demo": demo_objects}


def make_bags(work: Path, args: argparse.Namespace) -> dict[tuple[str, str], list[Path]]:
    """One bag per object for each (object set, scene) the sets use, each bag its own cameras (seed ``--seed`` plus
    the object's index: one seed for all would give every object the same relative poses); white bags are shared by
    both gravity rows."""
    bags: dict[tuple[str, str], list[Path]] = {}
    for object_set, scene, _, _ in SETS.values():
        key = (object_set, scene["scene"])
        if key not in bags:
            bags[key] = [make_bag(work / f"{object_set}_{scene['scene']}_{spec.name}", SyntheticBagOptions(
                object_set=object_set, object_name=spec.name, views=args.views, seed=args.seed + index, **scene))
                for index, spec in enumerate(OBJECTS[object_set]())]
    return bags


def table(results: dict[str, dict]) -> str:
    """The markdown table of every model's sets."""
    lines = ["| model | set | distinct pairs | RotAcc@15° | RotAcc@30° | median rot. err. (°) | random RotAcc@15° | "
             "random RotAcc@30° | s / estimate |", "|---|---|---|---|---|---|---|---|---|"]
    for label, sets in results.items():
        for name, row in sets.items():
            model, random = row["model"], row["random"]
            lines.append(f"| {label} | {name} | {model['distinct_pairs']} | {100 * model['rot_acc_15']:.1f} | "
                         f"{100 * model['rot_acc_30']:.1f} | {model['median_rot_err_deg']:.1f} | "
                         f"{100 * random['rot_acc_15']:.1f} | {100 * random['rot_acc_30']:.1f} | "
                         f"{row['seconds_per_estimate']:.1f} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", action="append", metavar="LABEL=PATH",
                        help="a model folder to measure, repeatable (default: the embedded model)")
    parser.add_argument("--heldout-samples", type=int, default=1,
                        help="evaluate_bag picks per held-out bag (one n = 2 pair each)")
    parser.add_argument("--demo-samples", type=int, default=4, help="evaluate_bag picks per demo bag")
    parser.add_argument("--views", type=int, default=12, help="views per bag")
    parser.add_argument("--preset", choices=("default", "fast"), default="fast")
    parser.add_argument("--set", action="append", choices=tuple(SETS), help="only these sets (default: all)")
    parser.add_argument("--seed", type=int, default=7070, help="scene, camera and pick seed of the fresh bags")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    models = dict(item.split("=", 1) for item in args.model or ["embedded="])
    torch.set_num_threads(args.threads)
    started = time.monotonic()
    bags_key = {"seed": args.seed, "seed_per_bag": True, "picks": "distinct openings", "views": args.views,
                "preset": args.preset,
                "heldout": list(BENCH_HELDOUT), "heldout_samples": args.heldout_samples,
                "demo_samples": args.demo_samples}
    previous = json.loads(args.out.read_text()) if args.out.is_file() else {}
    results = previous.get("results", {}) if previous.get("bags") == bags_key else {}
    with tempfile.TemporaryDirectory(prefix="idpose_novel_objects_") as folder:
        bags = make_bags(Path(folder), args)
        for label, path in models.items():
            estimator = make_estimator(EstimatorOptions(model_path=path, preset=args.preset))
            results[label] = dict(results.get(label, {}))
            for name, (object_set, scene, ground_truth, samples) in SETS.items():
                if args.set and name not in args.set:
                    continue
                protocol = EvaluationProtocol(getattr(args, samples), args.seed, (2,))
                results[label][name] = evaluate_set(bags[(object_set, scene["scene"])], ground_truth, estimator,
                                                    protocol)
                row = results[label][name]["model"]
                print(f"{label}, {name}: {row['distinct_pairs']} distinct pairs, RotAcc@30 "
                      f"{100 * row['rot_acc_30']:.1f} %", flush=True)
    print("\n" + table(results))
    result = {"bags": bags_key, "models": {**previous.get("models", {}), **models},
              "minutes": (time.monotonic() - started) / 60, "results": results}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out} ({result['minutes']:.0f} min)")


if __name__ == "__main__":
    main()
