#!/usr/bin/env python3
"""Depth segmentation on fresh tabletop scenes: mask IoU against the true mask, per failure type and overall.

Each view is its own seeded scene (``idpose_core.synthetic.tabletop``: the target on a textured table among
2-4 other objects, in a textured room, random light with shadows), seen by one RGB-D camera from above the
table, low (polar 82 deg, nearly level) to high (30 deg), 0.4-0.75 m away. Per failure type the scene stages
what makes segmentation hard:

- clutter: the scene as ``make_synthetic_bag --scene tabletop`` draws it;
- parts: a target whose head stands out in front of its body, turned towards the camera (a depth jump
  inside the object);
- touching: a box leaning against the target's side;
- backdrop: a panel standing 10-30 cm behind the target;
- off_centre: the camera aimed beside the target, whose centre sits about 30-65 % of the way to the image
  edge, every other object's at least 15 % farther out (``off_centre_camera``: the view is still about
  the target); and the same views again with a region of interest (off_centre_roi: a box around the
  target grown by 10-30 % on each side, as a detector gives); crowded: off-centre views where another
  object's centre is 15 % nearer the image centre (only a region of interest says which object the view
  is about), without and with (crowded_roi) that box;
- near_backdrop: a panel 0-4 cm behind the target's bounding ball, a wall it almost touches (parts of the
  target that rise over it, such as a brick's studs seen from level, stand against the panel at a depth step);
- on_box: the target standing on a textured box of its own size (1-1.2 times its width and depth, 0.6-1.2 times its
  height): one piece in depth with the box, or apart from it where a stereo camera reads nothing at the edge.

Targets are the six demo objects in turn, or with ``--targets heldout`` the catalogue's held-out objects (parts:
a generated head-and-body either way). The mask is what the
pipeline computes from the colour image, the depth and the intrinsics (``foreground_mask``: the depth
cut, with its fallbacks), without gravity; views where under 300 target pixels, or under half of its silhouette,
are in sight (a target hidden behind another object) are left out.
`--depth-noise` gives the depth as a camera reads it (relative Gaussian noise, rounded to millimetres), `--stereo`
as an active stereo camera does (noise growing with depth, no readings either side of an edge).
Prints mean and worst IoU and the share of views under 0.75 per row and overall (the six failure types) with the
number of views, and adds the run (the commit measured, the seed, the depth, the targets and the table) to
bench/results/mask_quality/summary.json; ``--out FILE`` also writes every view's row there.

    python bench/mask_quality.py [--seed 1000] [--views 8] [--size 320] [--depth-noise 0.003 | --stereo]
                                 [--targets demo|heldout] [--object-size 0.2]

``--object-size`` (m) sets the ball the target fits (20 cm by default; the cameras' distances grow with its square
root, and from 0.5 m the scene stands on the floor).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

import numpy as np  # noqa: E402 (after the path setup)

from bench.result_files import result_path  # noqa: E402
from idpose_core.preprocessing import foreground_mask, mask_iou  # noqa: E402
from idpose_core.synthetic.catalogue import BENCH_HELDOUT, heldout_objects  # noqa: E402
from idpose_core.synthetic.robot_views import pinhole_intrinsics  # noqa: E402
from idpose_core.synthetic.scenes import demo_objects  # noqa: E402
from idpose_core.synthetic.tabletop import (  # noqa: E402
    CHALLENGES,
    ROOM_HALF_SIDE,
    TARGET_RADIUS,
    TabletopRenderer,
    challenge_camera,
    loose_box,
    off_centre_camera,
    parts_target,
    random_layout,
    sensor_depth,
    stereo_depth,
)
from idpose_core.view_input import ViewInput  # noqa: E402

FOV_DEG = 60.0
POLAR_DEG, DISTANCE = (30.0, 82.0), (0.4, 0.75)
MIN_VISIBLE = 300  # px of the target that must be in sight
MIN_VISIBLE_SHARE = 0.5  # of the target's silhouette: a target mostly hidden behind another object is not in view
ROI_STREAM = 5  # the random stream of the regions of interest (and 6 of the crowded views'): as before the
# sixth failure type, so that the boxes stay the same
FLOOR_SIZE = 0.5  # m: an object this large stands on the floor, not on a table
EXTRA_ROWS = ("off_centre_roi", "crowded", "crowded_roi")  # off-centre views beside the failure types
SUMMARY_ABOUT = ("bench/mask_quality.py runs: per run the code measured (a commit; earlier code was run from its "
                 "checkout with this bench copied in), the seed, the depth noise and the mask IoU per failure type "
                 "(mean and worst); per-view rows only where a run wrote --out.")


def challenge_view(challenge: str, index: int, seed: int, size: int, crowded: bool = False,
                   depth_noise: float = 0.0, stereo: bool = False, targets: str = "demo",
                   object_size: float = 2 * TARGET_RADIUS) -> tuple[ViewInput, np.ndarray] | None:
    """(the view: colour, depth, intrinsics; the target's true mask) of scene ``index`` of a failure type, or
    None when too little of the target is in sight (under ``MIN_VISIBLE`` px, or under ``MIN_VISIBLE_SHARE`` of
    its silhouette: mostly hidden behind another object). ``crowded`` (off-centre only): another object nearer the
    image centre than the target. ``depth_noise``: the depth as a camera reads it (``sensor_depth``); ``stereo``:
    as an active stereo camera reads it (``stereo_depth``: noise growing with depth, no readings at edges).
    ``targets``: the demo objects in turn, or (``heldout``) the catalogue's held-out objects; ``object_size`` (m):
    the ball the target fits, the cameras' distances scaled with it (``scaled_distance``), on the floor from
    ``FLOOR_SIZE`` up."""
    rng = np.random.default_rng([seed, CHALLENGES.index(challenge), index] + [1] * crowded)
    pool = demo_objects() if targets == "demo" else heldout_objects(*BENCH_HELDOUT)
    target = parts_target(rng) if challenge == "parts" else pool[index % len(pool)]
    camera = None
    while camera is None:  # an off-centre view takes a new scene until a fair aim exists
        sphere = np.array([math.radians(rng.uniform(*POLAR_DEG)), rng.uniform(0.0, 2.0 * math.pi),
                           scaled_distance(rng.uniform(*DISTANCE), object_size)])
        layout = random_layout(target, rng, behind_azimuth=float(sphere[1]), challenge=challenge,
                               target_radius=object_size / 2, table=object_size < FLOOR_SIZE)
        camera = (off_centre_camera(sphere, layout, rng, FOV_DEG, crowded) if challenge == "off_centre"
                  else challenge_camera(sphere))
    with TabletopRenderer(layout, image_size=size, fov_deg=FOV_DEG) as renderer:
        frame = renderer.render(camera)
    with TabletopRenderer(dataclasses.replace(layout, distractors=()), image_size=size, fov_deg=FOV_DEG) as alone:
        silhouette = alone.render(camera).target_mask.sum()
    if frame.target_mask.sum() < max(MIN_VISIBLE, MIN_VISIBLE_SHARE * silhouette):
        return None
    depth = (stereo_depth(frame.depth, rng) if stereo else sensor_depth(frame.depth, rng, depth_noise) if depth_noise
             else frame.depth)
    return ViewInput(frame.rgb, depth=depth, intrinsics=pinhole_intrinsics(size, FOV_DEG)), frame.target_mask


def with_roi(view: ViewInput, truth: np.ndarray, seed: int, index: int, crowded: bool) -> ViewInput:
    """The view with a region of interest: a loose box around the target, as a detector would give."""
    box = loose_box(truth, np.random.default_rng([seed, ROI_STREAM + int(crowded), index]))
    return dataclasses.replace(view, roi=box)


def score(view: ViewInput, truth: np.ndarray, name: str, index: int) -> dict:
    """The pipeline's mask of one view against the truth: scene index, IoU and mask method (printed)."""
    found = foreground_mask(view)
    row = {"scene": index, "iou": mask_iou(found.mask, truth), "method": found.method, "confidence": found.confidence}
    print(f"  {name} {index}: IoU {row['iou']:.3f} ({found.method}, confidence {found.confidence:.2f})",
          file=sys.stderr)
    return row


def measure(seed: int, views: int, size: int, depth_noise: float = 0.0, stereo: bool = False,
            targets: str = "demo", object_size: float = 2 * TARGET_RADIUS) -> dict:
    """Per failure type, and the off-centre rows with a region of interest or a crowded centre (``EXTRA_ROWS``):
    every view's IoU and mask method (``challenge_view`` for the depth, the targets and their size)."""
    results: dict[str, list[dict]] = {}
    depth = {"depth_noise": depth_noise, "stereo": stereo, "targets": targets, "object_size": object_size}
    for challenge in CHALLENGES:
        results[challenge] = []
        for index in range(views):
            scene = challenge_view(challenge, index, seed, size, **depth)
            if scene is None:
                continue
            view, truth = scene
            results[challenge].append(score(view, truth, challenge, index))
            if challenge != "off_centre":
                continue
            results.setdefault("off_centre_roi", []).append(
                score(with_roi(view, truth, seed, index, False), truth, "off_centre_roi", index))
            crowded = challenge_view(challenge, index, seed, size, crowded=True, **depth)
            if crowded is not None:
                view, truth = crowded
                results.setdefault("crowded", []).append(score(view, truth, "crowded", index))
                results.setdefault("crowded_roi", []).append(
                    score(with_roi(view, truth, seed, index, True), truth, "crowded_roi", index))
    return results


def scaled_distance(distance: float, object_size: float) -> float:
    """A camera ``distance`` (m) drawn for a 20 cm object, for an object of ``object_size`` (m): times the square root
    of their sizes' ratio (a small object fills less of the image, a large one more: 0.25-0.47 m for 8 cm, 0.9-1.6 m
    for 1 m), inside the room's walls."""
    return min(distance * math.sqrt(object_size / (2 * TARGET_RADIUS)), ROOM_HALF_SIDE - 0.2)


LOW_IOU = 0.75  # a view under this IoU lost a large part of its object, or took in another


def summary(rows: list[dict]) -> dict:
    """The number of views, mean and worst IoU, and the share of views under ``LOW_IOU``."""
    values = np.array([row["iou"] for row in rows])
    return {"views": len(values), "mean": float(values.mean()), "worst": float(values.min()),
            "under_0.75": float(np.mean(values < LOW_IOU))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=1000, help="scene seed")
    parser.add_argument("--views", type=int, default=8, help="scenes per failure type")
    parser.add_argument("--size", type=int, default=320, help="image side (px)")
    parser.add_argument("--depth-noise", type=float, default=0.0,
                        help="depth noise as a share of each reading, then rounded to mm (0: exact renders)")
    parser.add_argument("--stereo", action="store_true",
                        help="depth as an active stereo camera reads it (noise growing with depth, holes at edges)")
    parser.add_argument("--targets", choices=("demo", "heldout"), default="demo",
                        help="the six demo objects, or the catalogue's held-out objects (parts: generated either way)")
    parser.add_argument("--object-size", type=float, default=2 * TARGET_RADIUS,
                        help="the ball the target fits (m; cameras farther in proportion; on the floor from 0.5 m)")
    parser.add_argument("--out", type=Path, default=None, help="JSON file for every view's row (default: none)")
    args = parser.parse_args()
    started = time.monotonic()
    results = measure(args.seed, args.views, args.size, args.depth_noise, args.stereo, args.targets, args.object_size)
    table = {challenge: summary(rows) for challenge, rows in results.items() if rows}
    table["all"] = summary([row for name, rows in results.items() if name not in EXTRA_ROWS for row in rows])
    print(f"| type (seed {args.seed}) | views | mean IoU | worst IoU | under {LOW_IOU} |\n|---|---|---|---|---|")
    for name, row in table.items():
        print(f"| {name} | {row['views']} | {row['mean']:.3f} | {row['worst']:.3f} | {100 * row['under_0.75']:.0f} % |")
    run = {"code": measured_code(), "seed": args.seed, "depth_noise": args.depth_noise, "stereo": args.stereo,
           "targets": args.targets, "object_size": args.object_size, "size": args.size,
           "summary": table, "seconds": round(time.monotonic() - started, 1)}
    summary_file = result_path("mask_quality", "summary.json")
    runs = json.loads(summary_file.read_text())["runs"] if summary_file.is_file() else []
    summary_file.parent.mkdir(parents=True, exist_ok=True)
    summary_file.write_text(json.dumps({"about": SUMMARY_ABOUT, "runs": [*runs, run]}, indent=1) + "\n")
    if args.out is not None:
        args.out.write_text(json.dumps({**run, "views": results}, indent=2) + "\n")
    print(f"{run['seconds']:.0f} s; {summary_file}" + (f", {args.out}" if args.out else ""))


def measured_code() -> str:
    """The commit of the checkout measured (with "+changes" when its tracked files other than the results differ
    from it: a run before this one has added to the summary)."""
    def git(*arguments: str) -> str:
        return subprocess.run(["git", *arguments], cwd=ROOT, capture_output=True, text=True).stdout.strip()

    commit = git("rev-parse", "--short", "HEAD") or "unknown"
    changed = git("status", "--porcelain", "--untracked-files=no", "--", ".", ":!bench/results")
    return commit + ("+changes" if changed else "")

if __name__ == "__main__":
    main()
