#!/usr/bin/env python3
"""The fused clouds in a picture: each view's object points in the anchor's frame, one colour per view, placed by
the seed (the true poses turned by up to 30 deg about the object, a diffusion estimate's kind of error) and by
the depth refinement, for a few objects of ``bench/depth_refinement.py``'s scenes (stereo depth, the pipeline's
masks, four views). Writes bench/results/depth_refinement/fused_clouds.png.

    python bench/depth_cloud_figure.py
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from bench.depth_refinement import FOV, IMAGE_SIZE, SIZES, render_scene, turned_truth
from bench.result_files import result_path
from idpose_core.cameras import pinhole_camera_matrix
from idpose_core.depth_fusion import refine_with_depth, view_cloud
from idpose_core.metrics import rotation_angle_deg
from idpose_core.preprocessing import foreground_mask
from idpose_core.synthetic.catalogue import BENCH_HELDOUT, heldout_objects
from idpose_core.synthetic.scenes import demo_objects
from idpose_core.synthetic.tabletop import stereo_depth
from idpose_core.view_input import ViewInput

OUT = result_path("depth_refinement", "fused_clouds.png")
COLOURS = ("tab:red", "tab:blue", "tab:green", "tab:orange")
POINTS_PER_VIEW = 1500


def scatter(axis, clouds, poses, title: str) -> None:
    """Each view's points placed by its pose, in the anchor's frame (drawn with z up: the optical -y)."""
    for k, (cloud, pose) in enumerate(zip(clouds, poses)):
        points = cloud.transformed(pose).points
        points = points[np.random.default_rng(k).permutation(len(points))[:POINTS_PER_VIEW]]
        axis.scatter(points[:, 0], points[:, 2], -points[:, 1], s=0.3, c=COLOURS[k],
                     label="anchor" if k == 0 else f"view {k}")
    axis.set_title(title, fontsize=8)
    axis.set_axis_off()
    axis.set_box_aspect((1, 1, 1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=8080)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    demo = {spec.name: spec for spec in demo_objects()}
    cases = [(demo["duck"], "typical"), (heldout_objects(*BENCH_HELDOUT)[1], "typical"), (demo["teddy"], "large")]
    figure = plt.figure(figsize=(9, 3 * len(cases)))
    intrinsics = pinhole_camera_matrix(IMAGE_SIZE, IMAGE_SIZE, FOV)
    for row, (spec, size) in enumerate(cases):
        radius, distances, table = SIZES[size]
        frames, cameras = render_scene(spec, radius, distances, table, args.seed + row)
        rng = np.random.default_rng(args.seed + row)
        views = [ViewInput(rgb=frame.rgb, depth=stereo_depth(frame.depth, rng), intrinsics=intrinsics,
                           gravity_up=camera[:3, :3].T @ [0.0, 0.0, 1.0]) for frame, camera in zip(frames, cameras)]
        masks = [foreground_mask(view).mask for view in views]
        truth = np.linalg.inv(cameras[0]) @ cameras
        seed = turned_truth(truth, np.linalg.inv(cameras[0])[:3, 3], rng)
        refined = refine_with_depth(views, masks, seed, radius / 20.0)
        clouds = [view_cloud(view, mask) for view, mask in zip(views, masks)]
        errors = [rotation_angle_deg(p[:3, :3], t[:3, :3]) for p, t in zip(refined.poses[1:], truth[1:])]
        seed_errors = [rotation_angle_deg(p[:3, :3], t[:3, :3]) for p, t in zip(seed[1:], truth[1:])]
        for column, (poses, title) in enumerate((
                (seed, f"{spec.name} ({size}), seed: "
                       f"{', '.join(f'{e:.0f}' for e in seed_errors)} deg off"),
                (refined.poses, f"refined ({sum(v.refined for v in refined.views[1:])} of 3 views): "
                                f"{', '.join(f'{e:.1f}' for e in errors)} deg off"),
                (truth, "true poses"))):
            axis = figure.add_subplot(len(cases), 3, 3 * row + column + 1, projection="3d")
            scatter(axis, clouds, poses, title)
    figure.legend(*figure.axes[0].get_legend_handles_labels(), loc="lower center", ncol=4, markerscale=10)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(args.out, dpi=110, bbox_inches="tight")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
