#!/usr/bin/env python3
"""One chained case of ``bench/depth_hypotheses.py`` drawn from above: four views of a held-out object, their
true and chosen cameras, each view's winning source and margin, and the object's fused cloud.

    python bench/depth_hypotheses_figure.py     # bench/results/depth_hypotheses/chained_case.png
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bench.depth_hypotheses import SIZES, chain_spheres, render  # noqa: E402
from bench.result_files import result_path  # noqa: E402
from idpose_core.cameras import pinhole_camera_matrix  # noqa: E402
from idpose_core.metrics import rotation_angle_deg  # noqa: E402
from idpose_core.pose_hypotheses import verify_with_depth  # noqa: E402
from idpose_core.preprocessing import foreground_mask  # noqa: E402
from idpose_core.synthetic.catalogue import BENCH_HELDOUT, heldout_objects  # noqa: E402
from idpose_core.synthetic.tabletop import stereo_depth  # noqa: E402
from idpose_core.view_input import ViewInput  # noqa: E402

FOV = 60.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=4242)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    objects = heldout_objects(*BENCH_HELDOUT)
    spec = objects[int(rng.integers(len(objects)))]
    radius, distances, table = SIZES["20 cm"]
    frames, cameras = render(spec, chain_spheres(rng, 4, distances), radius, table, rng)
    size = frames[0].rgb.shape[0]
    intrinsics = pinhole_camera_matrix(size, size, FOV)
    views = [ViewInput(rgb=f.rgb, depth=stereo_depth(f.depth, rng), intrinsics=intrinsics,
                       gravity_up=camera[:3, :3].T @ [0.0, 0.0, 1.0]) for f, camera in zip(frames, cameras)]
    masks = [foreground_mask(view).mask for view in views]
    n = len(views)
    result = verify_with_depth(views, masks, np.tile(np.eye(4), (n, 1, 1)), np.full((n, 4, 4), math.nan), 0.005)
    world = cameras[0]  # the anchor's frame to the world (z up, the object at the origin)
    chosen = world @ result.poses
    cloud = result.cloud.points @ world[:3, :3].T + world[:3, 3]
    figure, axis = plt.subplots(figsize=(6.5, 6.5))
    axis.scatter(cloud[:, 0], cloud[:, 1], s=2, c=result.cloud.colours / 255.0)
    for k in range(n):
        true_centre, centre = cameras[k][:3, 3], chosen[k][:3, 3]
        axis.plot(*true_centre[:2], "o", color="tab:green", ms=10, mfc="none")
        axis.plot(*centre[:2], "x", color="tab:red", ms=9)
        axis.annotate("", xy=true_centre[:2] + 0.08 * cameras[k][:2, 2], xytext=true_centre[:2],
                      arrowprops={"arrowstyle": "->", "color": "tab:green"})
        report = result.views[k]
        error = float(rotation_angle_deg(result.poses[k][:3, :3], (np.linalg.inv(cameras[0]) @ cameras[k])[:3, :3]))
        label = "anchor" if k == 0 else (f"view {k}: {report.source}, margin {report.margin:.2f}"
                                         f"{' (ambiguous)' if report.ambiguous else ''}, {error:.1f} deg off")
        axis.annotate(label, centre[:2], textcoords="offset points", xytext=(8, 6), fontsize=8)
    axis.set_aspect("equal")
    axis.set_xlabel("x (m)")
    axis.set_ylabel("y (m)")
    axis.set_title(f"{spec.name}, stereo depth, four views 30-60 deg apart\n"
                   "o true camera, x chosen camera; the fused cloud from above", fontsize=9)
    out = result_path("depth_hypotheses", "chained_case.png")
    figure.savefig(out, dpi=110, bbox_inches="tight")
    print(out)


if __name__ == "__main__":
    main()
