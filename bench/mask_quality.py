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
- off_centre: the camera aimed beside the target, which sits 55-95 % of the way to the image edge (often
  cut by it).

Targets are the six demo objects in turn (parts: a generated head-and-body). The mask is what the
pipeline computes from the colour image, the depth and the intrinsics (``foreground_mask``: the depth
cut, with its fallbacks), without gravity; views where under 300 target pixels are visible are left out.
Prints mean and worst IoU per type and overall with the number of views, and writes bench/results/
mask_quality_<seed>.json.

    python bench/mask_quality.py [--seed 1000] [--views 8] [--size 320]
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

import numpy as np  # noqa: E402 (after the path setup)

from idpose_core.preprocessing import foreground_mask, mask_iou  # noqa: E402
from idpose_core.synthetic.robot_views import pinhole_intrinsics  # noqa: E402
from idpose_core.synthetic.scenes import demo_objects  # noqa: E402
from idpose_core.synthetic.tabletop import (  # noqa: E402
    CHALLENGES,
    TabletopRenderer,
    challenge_camera,
    parts_target,
    random_layout,
)
from idpose_core.view_input import ViewInput  # noqa: E402

FOV_DEG = 60.0
POLAR_DEG, DISTANCE = (30.0, 82.0), (0.4, 0.75)
MIN_VISIBLE = 300  # px of the target that must be in sight


def challenge_view(challenge: str, index: int, seed: int, size: int) -> tuple[ViewInput, np.ndarray] | None:
    """(the view: colour, depth, intrinsics; the target's true mask) of scene ``index`` of a failure type, or
    None when too little of the target is in sight."""
    rng = np.random.default_rng([seed, CHALLENGES.index(challenge), index])
    target = parts_target(rng) if challenge == "parts" else demo_objects()[index % len(demo_objects())]
    sphere = np.array([math.radians(rng.uniform(*POLAR_DEG)), rng.uniform(0.0, 2.0 * math.pi),
                       rng.uniform(*DISTANCE)])
    layout = random_layout(target, rng, behind_azimuth=float(sphere[1]), challenge=challenge)
    with TabletopRenderer(layout, image_size=size, fov_deg=FOV_DEG) as renderer:
        frame = renderer.render(challenge_camera(sphere, rng, off_centre=challenge == "off_centre"))
    if frame.target_mask.sum() < MIN_VISIBLE:
        return None
    return ViewInput(frame.rgb, depth=frame.depth, intrinsics=pinhole_intrinsics(size, FOV_DEG)), frame.target_mask


def measure(seed: int, views: int, size: int) -> dict:
    """Per failure type: every view's IoU and mask method, with the summary."""
    results = {}
    for challenge in CHALLENGES:
        rows = []
        for index in range(views):
            scene = challenge_view(challenge, index, seed, size)
            if scene is None:
                continue
            view, truth = scene
            mask, method, _ = foreground_mask(view)
            rows.append({"scene": index, "iou": mask_iou(mask, truth), "method": method})
            print(f"  {challenge} {index}: IoU {rows[-1]['iou']:.3f} ({method})", file=sys.stderr)
        results[challenge] = rows
    return results


def summary(rows: list[dict]) -> dict:
    values = [row["iou"] for row in rows]
    return {"views": len(values), "mean": float(np.mean(values)), "worst": float(np.min(values))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=1000, help="scene seed")
    parser.add_argument("--views", type=int, default=8, help="scenes per failure type")
    parser.add_argument("--size", type=int, default=320, help="image side (px)")
    parser.add_argument("--out", type=Path, default=None,
                        help="JSON file (default bench/results/mask_quality_<seed>.json)")
    args = parser.parse_args()
    started = time.monotonic()
    results = measure(args.seed, args.views, args.size)
    table = {challenge: summary(rows) for challenge, rows in results.items() if rows}
    table["all"] = summary([row for rows in results.values() for row in rows])
    print(f"| type (seed {args.seed}) | views | mean IoU | worst IoU |\n|---|---|---|---|")
    for name, row in table.items():
        print(f"| {name} | {row['views']} | {row['mean']:.3f} | {row['worst']:.3f} |")
    out = args.out or ROOT / "bench" / "results" / f"mask_quality_{args.seed}.json"
    out.write_text(json.dumps({"seed": args.seed, "size": args.size, "summary": table, "views": results,
                               "seconds": time.monotonic() - started}, indent=2) + "\n")
    print(f"{time.monotonic() - started:.0f} s; {out}")


if __name__ == "__main__":
    main()
