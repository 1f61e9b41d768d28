#!/usr/bin/env python3
"""Accuracy of the demo model on fresh renders (cameras no training run used), n = 2, vs random poses.

Two object sets: held-out views of the demo objects (the model's training objects) and unseen
objects. Per pair: the grid-search inversion check and, with ``--solver``, the ID-Pose solver
(``estimate_poses``, the given preset with the model's ``solver_defaults``). Prints a table and
writes JSON.

    python bench/demo_model_accuracy.py --pairs-per-object 8 --solver fast --out /tmp/demo_acc.json
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

import numpy as np  # noqa: E402 (after the path setup)
import torch
from tqdm import tqdm

from idpose_core.demo_model import EMBEDDED_MODEL_DIR, DemoPredictor
from idpose_core.demo_model.grid_check import grid_search, pose_grid, random_pose_errors, rotation_errors
from idpose_core.demo_model.training_data import make_pairs, random_pairs, render_views
from idpose_core.solver import SolverConfig, estimate_poses
from idpose_core.synthetic.scenes import demo_objects, unseen_objects

GRID_POLARS_DEG = (-60.0, -30.0, 0.0, 30.0, 60.0)


def accuracy(errors: np.ndarray) -> dict[str, float]:
    return {"pairs": int(errors.size), "rot_acc_15": float(np.mean(errors < 15)),
            "rot_acc_30": float(np.mean(errors < 30)), "median_rot_err_deg": float(np.median(errors))}


def evaluate(predictor: DemoPredictor, specs, args, seed: int, label: str) -> dict:
    views = render_views(specs, args.views_per_object, args.image_size, seed)
    rng = np.random.default_rng(seed)
    pairs = make_pairs(views, *random_pairs(views, rng, args.pairs_per_object * len(specs)), lambda x: x)
    cameras = (views.cameras[pairs.object_index, pairs.reference_index],
               views.cameras[pairs.object_index, pairs.target_index])
    t = int(round(predictor.solver_defaults.get("probe_t", 0.2) * predictor.num_train_timesteps))
    started = time.monotonic()
    grid = grid_search(predictor, pairs.reference, pairs.target, pose_grid(args.azimuths, GRID_POLARS_DEG), t,
                       noise_samples=args.noise_samples)
    result = {"grid": {**accuracy(rotation_errors(grid, *cameras)), "seconds": time.monotonic() - started}}
    random_errors = np.concatenate([random_pose_errors(*cameras, rng, GRID_POLARS_DEG) for _ in range(50)])
    result["random"] = accuracy(random_errors)
    if args.solver:
        config = SolverConfig.preset(args.solver, **predictor.solver_defaults)
        started = time.monotonic()
        estimates = [estimate_poses(predictor, torch.stack([ref, tgt]), config).rel_poses[0]
                     for ref, tgt in tqdm(zip(pairs.reference, pairs.target), total=len(pairs.pose),
                                          desc=f"solver ({args.solver}) on {label}")]
        result["solver"] = {**accuracy(rotation_errors(np.stack(estimates), *cameras)),
                            "seconds_per_pair": (time.monotonic() - started) / len(estimates)}
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", type=Path, default=EMBEDDED_MODEL_DIR)
    parser.add_argument("--pairs-per-object", type=int, default=6)
    parser.add_argument("--views-per-object", type=int, default=24)
    parser.add_argument("--image-size", type=int, default=128)
    parser.add_argument("--azimuths", type=int, default=24)
    parser.add_argument("--noise-samples", type=int, default=4)
    parser.add_argument("--solver", choices=["fast", "default"], default=None)
    parser.add_argument("--unseen-objects", type=int, default=6)
    parser.add_argument("--seed", type=int, default=777, help="render seed (training uses 0 and 1000)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    predictor = DemoPredictor.from_pretrained(args.model)
    report = {"model": str(args.model), "arguments": {k: str(v) for k, v in vars(args).items()},
              "demo_heldout": evaluate(predictor, demo_objects(), args, args.seed, "demo objects"),
              "unseen": evaluate(predictor, unseen_objects(args.unseen_objects), args, args.seed + 1, "unseen")}
    print(f"{'set':<14}{'method':<9}{'pairs':>6}{'@15':>7}{'@30':>7}{'median':>9}")
    for name in ("demo_heldout", "unseen"):
        for method, row in report[name].items():
            print(f"{name:<14}{method:<9}{row['pairs']:>6}{row['rot_acc_15']:>7.0%}{row['rot_acc_30']:>7.0%}"
                  f"{row['median_rot_err_deg']:>8.1f}d")
    if args.out:
        args.out.write_text(json.dumps(report, indent=2) + "\n")


if __name__ == "__main__":
    main()
