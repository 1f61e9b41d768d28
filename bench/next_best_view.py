#!/usr/bin/env python3
"""Does the suggested next view settle an estimate? A closed loop per start and capture policy.

Per start (a held-out benchmark object, ``idpose_core.synthetic.catalogue.BENCH_HELDOUT``, never trained on, under a
random lamp; two random reachable cameras at least 30 deg apart, exact gravity in every view) each policy of
``idpose_core.evaluation.active_capture.POLICIES`` runs its own loop: estimate (``--preset``), add the camera it
picks, estimate again, up to ``--views`` views. Per policy and view count: RotAcc@15/@30 and the median rotation
error of every non-anchor view, the same for the start's second view alone (does a new view fix an old one?),
the share flagged ambiguous, predictor samples per estimate, beside a random pose that knows the polar angle (as
gravity does: a random azimuth) scored on the same views. The two-view rows are the same estimate for every
policy. Pairs are distinct: one object and camera pair per start and view. Prints the table, writes
bench/results/next_best_view/next_best_view.json and .md.

    python bench/next_best_view.py --model training/novel_objects --starts 48
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

import numpy as np  # noqa: E402 (after the path setup)
import torch  # noqa: E402

from bench.result_files import result_path  # noqa: E402
from idpose_core.cameras import first_camera_frame_poses  # noqa: E402
from idpose_core.evaluation.active_capture import POLICIES, CaptureStart, LoopStep, random_starts, run_loop  # noqa: E402
from idpose_core.metrics import rotation_angle_deg  # noqa: E402
from idpose_core.model_loading import load_predictor  # noqa: E402
from idpose_core.next_view import ReachableSet  # noqa: E402
from idpose_core.pipeline import PipelineSettings  # noqa: E402
from idpose_core.solver import SolverConfig  # noqa: E402
from idpose_core.solver.config import PRESETS  # noqa: E402
from idpose_core.synthetic.catalogue import BENCH_HELDOUT, heldout_objects  # noqa: E402
from idpose_core.synthetic.scenes import CAMERA_RADIUS, random_light  # noqa: E402

OUT = result_path("next_best_view")
RANDOM_DRAWS = 200  # random azimuths per view for the random-pose baseline


def random_pose_errors(start: CaptureStart, cameras: list[np.ndarray], rng: np.random.Generator) -> np.ndarray:
    """Rotation errors (views - 1, RANDOM_DRAWS) of random poses that know each view's polar angle: its true
    polar, a uniform azimuth."""
    truth = first_camera_frame_poses(np.stack([start.anchor, *cameras]))
    errors = []
    for k, camera in enumerate(cameras, start=1):
        guesses = np.tile(camera, (RANDOM_DRAWS, 1))
        guesses[:, 1] = rng.uniform(-math.pi, math.pi, RANDOM_DRAWS)
        poses = first_camera_frame_poses(np.vstack([start.anchor, guesses]))[1:]
        errors.append(rotation_angle_deg(poses[:, :3, :3], truth[k, :3, :3]))
    return np.array(errors)


def true_cameras_deg(start: CaptureStart, steps: list[LoopStep]) -> list[list[float]]:
    """(polar, azimuth) in degrees of every camera of a loop, the anchor first, in the estimate's world (the
    anchor at azimuth 0)."""
    cameras = [start.anchor, start.second, *[step.next_camera for step in steps[:-1]]]
    return [[round(math.degrees(c[0]), 1), round((math.degrees(c[1] - start.anchor[1]) + 180.0) % 360.0 - 180.0, 1)]
            for c in cameras]


def share(errors: np.ndarray, threshold: float) -> float:
    return float(np.mean(errors <= threshold))


def summarise(loops: dict[str, list[list[LoopStep]]], baseline: list[np.ndarray]) -> list[dict]:
    """One row per policy and view count."""
    rows = []
    for policy, per_start in loops.items():
        for index in range(len(per_start[0])):
            steps = [steps[index] for steps in per_start]
            errors = np.concatenate([step.rotation_errors_deg for step in steps])
            first = np.array([step.rotation_errors_deg[0] for step in steps])
            views = steps[0].views
            chance = np.concatenate([draws[:views - 1].ravel() for draws in baseline])
            rows.append({"policy": policy, "views": views, "starts": len(steps), "distinct_pairs": len(errors),
                         "rot_acc_15": share(errors, 15.0), "rot_acc_30": share(errors, 30.0),
                         "median_rot_err_deg": float(np.median(errors)),
                         "second_view_rot_acc_30": share(first, 30.0),
                         "second_view_median_deg": float(np.median(first)),
                         "ambiguous_share": float(np.mean(np.concatenate([step.ambiguous for step in steps]))),
                         "forward_samples": float(np.mean([step.forward_samples for step in steps])),
                         "random_rot_acc_15": share(chance, 15.0), "random_rot_acc_30": share(chance, 30.0)})
    return rows


def table(rows: list[dict]) -> str:
    """The markdown table of the summary rows."""
    lines = ["| policy | views | pairs | RotAcc@15 | RotAcc@30 | median deg | 2nd view @30 | 2nd view median | "
             "ambiguous | samples | random @15/@30 |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['policy']} | {r['views']} | {r['distinct_pairs']} | {100 * r['rot_acc_15']:.1f} % | "
                     f"{100 * r['rot_acc_30']:.1f} % | {r['median_rot_err_deg']:.1f} | "
                     f"{100 * r['second_view_rot_acc_30']:.1f} % | {r['second_view_median_deg']:.1f} | "
                     f"{100 * r['ambiguous_share']:.0f} % | {r['forward_samples']:.0f} | "
                     f"{100 * r['random_rot_acc_15']:.1f} / {100 * r['random_rot_acc_30']:.1f} % |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", default="training/novel_objects", help="model folder (or LDM .ckpt)")
    parser.add_argument("--starts", type=int, default=48, help="loops per policy (objects cycle after 48)")
    parser.add_argument("--views", type=int, default=5, help="views at the end of a loop")
    parser.add_argument("--preset", default="live", choices=sorted(PRESETS))
    parser.add_argument("--keep-top", type=int, default=None,
                        help="candidates kept per view (the preset's when absent): a later view re-chooses among them")
    parser.add_argument("--policies", nargs="+", default=list(POLICIES), choices=POLICIES)
    parser.add_argument("--image-size", type=int, default=256, help="render side in pixels")
    parser.add_argument("--seed", type=int, default=9090, help="starts, lights and the random policy's draws")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    if args.views < 3:
        parser.error("--views must be at least 3: a loop adds at least one view")

    torch.set_num_threads(args.threads)
    predictor = load_predictor(args.model, device="cpu")
    reachable = ReachableSet()
    rng = np.random.default_rng(args.seed)
    objects = heldout_objects(*BENCH_HELDOUT)
    lights = [random_light(rng) for _ in objects]
    starts = random_starts(objects, lights, args.starts, reachable, CAMERA_RADIUS, rng)
    overrides = {} if args.keep_top is None else {"keep_top": args.keep_top}
    settings = PipelineSettings(SolverConfig.preset(args.preset, **overrides), object_distance=CAMERA_RADIUS,
                                reachable=reachable)
    loops: dict[str, list[list[LoopStep]]] = {policy: [] for policy in args.policies}
    baseline = []
    begun, total, done = time.time(), len(starts) * len(args.policies), 0
    for k, start in enumerate(starts):
        for policy in args.policies:
            steps = run_loop(predictor, start, policy, settings, args.views, args.image_size,
                             np.random.default_rng([args.seed, k]))
            loops[policy].append(steps)
            done += 1
            last = steps[-1].rotation_errors_deg
            print(f"[{100 * done / total:5.1f} %] start {k} ({start.spec.name}) {policy}: final errors "
                  f"{np.round(last).astype(int).tolist()} deg, {time.time() - begun:.0f} s", flush=True)
        cameras = [start.second, *[step.next_camera for step in loops[args.policies[0]][-1][:-1]]]
        baseline.append(random_pose_errors(start, cameras, np.random.default_rng([args.seed, k, 1])))

    rows = summarise(loops, baseline)
    print(table(rows))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({
        "model": args.model, "preset": args.preset, "solver_overrides": overrides, "starts": args.starts,
        "views": args.views, "seed": args.seed,
        "objects": f"BENCH_HELDOUT {BENCH_HELDOUT}: {len(objects)} held-out objects, a random lamp each",
        "reachable": {"polar_deg": reachable.polar_deg, "azimuth_deg": reachable.azimuth_deg,
                      "step_deg": reachable.step_deg},
        "minutes": (time.time() - begun) / 60.0, "rows": rows,
        "truth_deg": {policy: [true_cameras_deg(start, steps) for start, steps in zip(starts, per_start)]
                      for policy, per_start in loops.items()},
        "loops": {policy: [[{"views": s.views, "errors_deg": s.rotation_errors_deg.round(2).tolist(),
                             "ambiguous": s.ambiguous.tolist(),
                             "spheres_deg": np.degrees(s.spheres[:, :2]).round(1).tolist(),
                             "rivals_deg": np.degrees(s.rivals[:, :2]).round(1).tolist(),
                             "next_camera_deg": None if s.next_camera is None
                             else np.degrees(s.next_camera[:2]).round(1).tolist()} for s in steps]
                           for steps in per_start] for policy, per_start in loops.items()}}, indent=1) + "\n")
    args.out.with_suffix(".md").write_text(table(rows) + "\n")
    print(f"wrote {args.out} and {args.out.with_suffix('.md').name}")


if __name__ == "__main__":
    main()
