#!/usr/bin/env python3
"""The masks' second pass across views on fresh tabletop scenes: mask IoU of each view before and after the pass.

Each scene (``idpose_core.synthetic.tabletop``) is seen by three RGB-D cameras 35 deg apart in azimuth, from low
(polar 84 deg) to high (55 deg), 0.45-0.7 m away; the scenes cycle through a wall 0-4 cm behind the target
(``near_backdrop``), a panel 10-30 cm behind it (``backdrop``) and plain clutter, the target turned at random.
Each view's mask is the pipeline's (``foreground_mask``); the views are posed with their true poses (the pass is
measured alone, not the poses), their clouds fused as the pipeline fuses them (a view whose mask confidence is under
``PipelineSettings.min_mask_confidence`` stays out), then ``cross_view_masks`` gives every view its second pass.
Prints mean and worst IoU before and after, the share of views under 0.75, the largest loss and gain of one view,
and the pass's seconds per view; writes bench/results/mask_quality/cross_view.json (``--out`` for another file).
A scene where a view shows under 300 px of the target is left out.

    python bench/mask_cross_view.py [--seed 5151] [--scenes 12] [--targets demo|heldout] [--stereo]
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

import numpy as np  # noqa: E402 (after the path setup)

from bench.mask_quality import LOW_IOU, MIN_VISIBLE, measured_code  # noqa: E402
from bench.result_files import result_path  # noqa: E402
from idpose_core.depth_fusion import MaskPass, cross_view_masks, fused_cloud, view_cloud  # noqa: E402
from idpose_core.pipeline import PipelineSettings, mask_trusted  # noqa: E402
from idpose_core.preprocessing import ForegroundMask, foreground_mask, mask_iou  # noqa: E402
from idpose_core.synthetic.catalogue import BENCH_HELDOUT, heldout_objects  # noqa: E402
from idpose_core.synthetic.robot_views import pinhole_intrinsics  # noqa: E402
from idpose_core.synthetic.scenes import demo_objects  # noqa: E402
from idpose_core.synthetic.tabletop import TabletopRenderer, challenge_camera, random_layout, stereo_depth  # noqa: E402
from idpose_core.view_input import ViewInput  # noqa: E402

FOV_DEG, SIZE = 60.0, 320
SCENE_CHALLENGES = ("near_backdrop", "backdrop", "clutter")
CAMERAS_DEG = ((0.0, 0.0), (-6.0, 35.0), (-3.0, -35.0))  # (polar, azimuth) offsets of the three cameras
POLAR_DEG, DISTANCE = (55.0, 84.0), (0.45, 0.7)


def scene_views(index: int, seed: int, targets: str, stereo: bool) -> tuple[list[ViewInput], list, np.ndarray] | None:
    """Scene ``index``: its three views (colour, depth, intrinsics), their true masks and their poses in the first
    camera's frame; None when a view shows under ``MIN_VISIBLE`` px of the target."""
    rng = np.random.default_rng([seed, index])
    pool = demo_objects() if targets == "demo" else heldout_objects(*BENCH_HELDOUT)
    azimuth = rng.uniform(0.0, 2.0 * math.pi)
    polar, distance = rng.uniform(*POLAR_DEG), rng.uniform(*DISTANCE)
    layout = random_layout(pool[index % len(pool)], rng, behind_azimuth=float(azimuth),
                           challenge=SCENE_CHALLENGES[index % len(SCENE_CHALLENGES)])
    layout = dataclasses.replace(layout, target=dataclasses.replace(layout.target, yaw_deg=float(rng.uniform(0, 360))))
    cameras = [challenge_camera(np.array([math.radians(polar + dp), azimuth + math.radians(da), distance]))
               for dp, da in CAMERAS_DEG]
    with TabletopRenderer(layout, SIZE, FOV_DEG) as renderer:
        frames = [renderer.render(camera) for camera in cameras]
    if min(frame.target_mask.sum() for frame in frames) < MIN_VISIBLE:
        return None
    intrinsics = pinhole_intrinsics(SIZE, FOV_DEG)
    views = [ViewInput(f.rgb, depth=stereo_depth(f.depth, rng) if stereo else f.depth, intrinsics=intrinsics)
             for f in frames]
    return views, [f.target_mask for f in frames], np.stack([np.linalg.inv(cameras[0]) @ c for c in cameras])


def second_pass(views: list[ViewInput], poses: np.ndarray) -> tuple[list[ForegroundMask], list[MaskPass], float] | None:
    """The views' masks as the pipeline makes them, their clouds fused on ``poses`` as the pipeline fuses them (the
    defaults: a view under ``min_mask_confidence`` stays out), and every view's second pass with the seconds it took;
    None when no view has a cloud to fuse."""
    minimum, voxel = PipelineSettings.min_mask_confidence, PipelineSettings.cloud_voxel_size
    found = [foreground_mask(view) for view in views]
    fused = [mask_trusted(item.confidence, minimum) for item in found]
    clouds = [view_cloud(view, item.mask) for view, item in zip(views, found)]
    kept = [k for k, cloud in enumerate(clouds) if cloud is not None and fused[k]]
    if not kept:
        return None
    cloud = fused_cloud([clouds[k] for k in kept], [poses[k] for k in kept], voxel)
    started = time.perf_counter()
    done = cross_view_masks(views, [item.mask for item in found], poses, cloud.points, voxel, [True] * len(views),
                            fused)
    return found, done, time.perf_counter() - started


def measure(seed: int, scenes: int, targets: str, stereo: bool) -> tuple[list[dict], float]:
    """Every view's IoU before and after the pass, and the pass's seconds per view."""
    rows, seconds, passed = [], 0.0, 0
    for index in range(scenes):
        scene = scene_views(index, seed, targets, stereo)
        if scene is None:
            continue
        views, truth, poses = scene
        passes = second_pass(views, poses)
        if passes is None:
            continue
        found, done, spent = passes
        seconds += spent
        passed += len(found)
        for k, (item, after) in enumerate(zip(found, done)):
            rows.append({"scene": index, "view": k, "before": mask_iou(item.mask, truth[k]),
                         "after": mask_iou(after.mask, truth[k]), "added": after.added, "removed": after.removed,
                         "confidence": item.confidence})
            print(f"  scene {index} view {k}: IoU {rows[-1]['before']:.3f} -> {rows[-1]['after']:.3f} "
                  f"({100 * (index + 1) / scenes:.0f} %)", file=sys.stderr)
    return rows, seconds / max(passed, 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=5151, help="scene seed")
    parser.add_argument("--scenes", type=int, default=12, help="scenes (three views each)")
    parser.add_argument("--targets", choices=("demo", "heldout"), default="demo")
    parser.add_argument("--stereo", action="store_true", help="depth as an active stereo camera reads it")
    parser.add_argument("--out", type=Path, default=None, help="JSON file (default: bench/results/mask_quality/"
                                                               "cross_view.json, appended)")
    args = parser.parse_args()
    rows, seconds = measure(args.seed, args.scenes, args.targets, args.stereo)
    before, after = (np.array([row[key] for row in rows]) for key in ("before", "after"))
    change = after - before
    table = {"views": len(rows), "before": {"mean": float(before.mean()), "worst": float(before.min()),
                                            "under_0.75": float(np.mean(before < LOW_IOU))},
             "after": {"mean": float(after.mean()), "worst": float(after.min()),
                       "under_0.75": float(np.mean(after < LOW_IOU))},
             "largest_loss": float(max(0.0, -change.min())), "largest_gain": float(max(0.0, change.max())),
             "views_changed": int(np.sum(np.abs(change) > 1e-9)), "seconds_per_view": seconds}
    print(f"| cross-view pass (seed {args.seed}, {args.targets}, {'stereo' if args.stereo else 'exact'}) | views | "
          f"mean IoU | worst IoU | under {LOW_IOU} |\n|---|---|---|---|---|")
    for name in ("before", "after"):
        row = table[name]
        print(f"| {name} | {len(rows)} | {row['mean']:.3f} | {row['worst']:.3f} | {100 * row['under_0.75']:.0f} % |")
    print(f"largest loss {table['largest_loss']:.3f}, largest gain {table['largest_gain']:.3f}, "
          f"{table['views_changed']} views changed, {seconds:.2f} s a view")
    run = {"code": measured_code(), "seed": args.seed, "targets": args.targets, "stereo": args.stereo,
           "scenes": args.scenes, "summary": table}
    out = args.out or result_path("mask_quality", "cross_view.json")
    runs = json.loads(out.read_text())["runs"] if out.is_file() else []
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"about": "bench/mask_cross_view.py runs", "runs": [*runs, {**run, "views": rows}]},
                              indent=1) + "\n")
    print(out)


if __name__ == "__main__":
    main()
