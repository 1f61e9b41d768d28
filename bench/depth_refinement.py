#!/usr/bin/env python3
"""Depth refinement measured on fresh tabletop scenes with known cameras, for objects of every size.

Per object set (the six demo objects; held-out benchmark objects, ``catalogue.BENCH_HELDOUT``: never trained on,
never ``random_urdfs`` 900-999), per size (small: an 8 cm object at 25-35 cm; typical: 20 cm at 45-65 cm; large:
1 m at 1.3-1.6 m, standing on the floor as a chair before a mobile robot) and scene: four roll-free views with
gravity, rendered with exact depth and with a RealSense-like stereo depth (noise growing with depth squared,
shadows beside near surfaces: ``tabletop.stereo_depth``).
Each view's mask is the pipeline's (``foreground_mask``: cut by depth, with its fallbacks; scored against the true
mask), then for n = 2 (views 0, 1) and
n = 4 the poses are refined (``refine_with_depth``) from four seeds:

- ``diffusion``: the pipeline's own estimate (``--preset``, the model of ``--model``), run once per scene and n on
  the stereo-depth views and used for both depths (the mask it cuts hardly changes the estimate);
- ``within 30 deg``: the true pose turned by 0-30 deg about a random axis (how the refinement does where the
  diffusion seed is that close, whatever the model);
- ``identity`` and ``random``: no diffusion seed (all cameras alike; uniformly random rotations).

Rows ``diffusion only`` give the diffusion poses unrefined. For every non-anchor view: the rotation error (deg)
and camera position error (cm) against the truth, whether it was refined, and whether the gate let it get more
than 5 deg worse than its seed; per estimate the fused cloud's mean distance to the true visible surface (mm; the
exact depth of every view under the true masks) and the refinement's seconds per view.

    python bench/depth_refinement.py --scenes 4     # the table, also in bench/results/depth_refinement/ (.json, .md)
    python bench/depth_refinement.py --no-diffusion # the refinement rows only, no model
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

import numpy as np
import torch
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from bench.result_files import result_path
from idpose_core.cameras import pinhole_camera_matrix
from idpose_core.depth_fusion import refine_with_depth
from idpose_core.metrics import rotation_angle_deg
from idpose_core.model_loading import load_predictor
from idpose_core.pipeline import PipelineSettings, estimate_view_poses
from idpose_core.preprocessing import foreground_mask, mask_iou
from idpose_core.segmentation import backproject
from idpose_core.solver import SolverConfig
from idpose_core.solver.config import PRESETS
from idpose_core.synthetic.catalogue import BENCH_HELDOUT, heldout_objects
from idpose_core.synthetic.scenes import demo_objects
from idpose_core.synthetic.tabletop import (
    TabletopRenderer,
    challenge_camera,
    random_layout,
    stereo_depth,
    tabletop_cameras,
)
from idpose_core.view_input import ViewInput

OUT = result_path("depth_refinement")
# name -> (radius of the object's ball in m, camera distances in m, on a table)
SIZES = {"small": (0.04, (0.25, 0.35), True), "typical": (0.1, (0.45, 0.65), True), "large": (0.5, (1.3, 1.6), False)}
OBJECTS = {"demo": demo_objects, "held-out": lambda: heldout_objects(*BENCH_HELDOUT)}
VIEWS, IMAGE_SIZE, FOV = 4, 320, 60.0
SEEDS = ("diffusion", "within 30 deg", "identity", "random")
WORSE_DEG = 5.0


def render_scene(spec, radius: float, distances: tuple[float, float], table: bool, seed: int):
    """Colour, exact depth and true mask of ``VIEWS`` roll-free cameras around ``spec`` fitted into ``radius`` on a
    tabletop (or the floor), and the cameras (optical-to-world, the object's centre at the origin)."""
    rng = np.random.default_rng(seed)
    spheres = tabletop_cameras(rng, VIEWS, distance=distances)
    layout = random_layout(spec, rng, behind_azimuth=float(spheres[0, 1]), target_radius=radius, table=table)
    cameras = [challenge_camera(sphere) for sphere in spheres]
    with TabletopRenderer(layout, IMAGE_SIZE, FOV, far=max(6.0, 4 * distances[1])) as renderer:
        return [renderer.render(camera) for camera in cameras], np.stack(cameras)


def turned_truth(truth: np.ndarray, centre: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Each non-anchor camera turned by 0-30 deg about a random axis through the object's ``centre`` (3,): a
    diffusion estimate's kind of error, in rotation and position alike."""
    seeds = truth.copy()
    for k in range(1, len(truth)):
        axis = rng.normal(size=3)
        turn = np.eye(4)
        turn[:3, :3] = Rotation.from_rotvec(axis / np.linalg.norm(axis) * math.radians(rng.uniform(0.0, 30.0))
                                            ).as_matrix()
        turn[:3, 3] = centre - turn[:3, :3] @ centre
        seeds[k] = turn @ truth[k]
    return seeds


def no_seed(kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    """Identity or uniformly random rotations for every view (the anchor the identity)."""
    poses = np.tile(np.eye(4), (n, 1, 1))
    if kind == "random":
        poses[1:, :3, :3] = Rotation.random(n - 1, random_state=rng.integers(2**31)).as_matrix()
    return poses


def view_errors(poses: np.ndarray, truth: np.ndarray) -> list[tuple[float, float]]:
    """(rotation error deg, position error cm) of every non-anchor view."""
    return [(rotation_angle_deg(poses[k, :3, :3], truth[k, :3, :3]),
             100.0 * float(np.linalg.norm(poses[k, :3, 3] - truth[k, :3, 3]))) for k in range(1, len(poses))]


def true_surface(frames, truth: np.ndarray, intrinsics: np.ndarray) -> cKDTree:
    """The object's visible surface from every camera (exact depth under the true masks) in the anchor's frame."""
    parts = []
    for frame, pose in zip(frames, truth):
        points, valid = backproject(frame.depth, intrinsics)
        parts.append(points[valid & frame.target_mask] @ pose[:3, :3].T + pose[:3, 3])
    return cKDTree(np.concatenate(parts))


def measure_scene(spec, size: str, seed: int, predictor, preset: str) -> list[dict]:
    """Every (depth, n, row) record of one scene."""
    radius, distances, table = SIZES[size]
    frames, cameras = render_scene(spec, radius, distances, table, seed)
    intrinsics = pinhole_camera_matrix(IMAGE_SIZE, IMAGE_SIZE, FOV)
    truth = np.linalg.inv(cameras[0]) @ cameras
    gravity = [camera[:3, :3].T @ [0.0, 0.0, 1.0] for camera in cameras]
    surface = true_surface(frames, truth, intrinsics)
    rng = np.random.default_rng(seed)
    depths = {"exact": [frame.depth for frame in frames],
              "stereo": [stereo_depth(frame.depth, rng) for frame in frames]}
    views = {kind: [ViewInput(rgb=frame.rgb, depth=depth, intrinsics=intrinsics, gravity_up=up)
                    for frame, depth, up in zip(frames, values, gravity)] for kind, values in depths.items()}
    diffusion = {}
    if predictor is not None:
        settings = PipelineSettings(SolverConfig.preset(preset), depth_refinement=False)
        for n in (2, VIEWS):
            diffusion[n] = estimate_view_poses(predictor, views["stereo"][:n], settings).poses
    records = []
    for depth_kind, scene_views in views.items():
        masks, ious = [], []
        for view, frame in zip(scene_views, frames):
            mask = foreground_mask(view).mask
            masks.append(mask)
            ious.append(mask_iou(mask, frame.target_mask))
        base = {"object": spec.name, "size": size, "scene_seed": seed, "depth": depth_kind, "mask_iou": ious}
        for n in (2, VIEWS):
            centre = np.linalg.inv(cameras[0])[:3, 3]  # the object's centre (the world origin) in the anchor's frame
            seeds = {"within 30 deg": turned_truth(truth[:n], centre, rng), "identity": no_seed("identity", n, rng),
                     "random": no_seed("random", n, rng)}
            if n in diffusion:
                seeds = {"diffusion": diffusion[n], **seeds}
                records.append({**base, "n": n, "row": "diffusion only", "seed_errors": view_errors(diffusion[n],
                                                                                                    truth[:n]),
                                "errors": view_errors(diffusion[n], truth[:n]), "refined": [False] * (n - 1)})
            for name, seed_poses in seeds.items():
                start = time.perf_counter()
                refined = refine_with_depth(scene_views[:n], masks[:n], seed_poses, radius / 20.0)
                seconds = time.perf_counter() - start
                record = {**base, "n": n, "row": f"{name} + refinement", "seed_errors": view_errors(seed_poses,
                                                                                                   truth[:n])}
                if refined is None:
                    records.append({**record, "errors": record["seed_errors"], "refined": [False] * (n - 1),
                                    "note": "no depth on the anchor's object"})
                    continue
                distances_mm = surface.query(refined.cloud.points)[0] * 1000.0
                records.append({**record, "errors": view_errors(refined.poses, truth[:n]),
                                "refined": [view.refined for view in refined.views[1:]],
                                "notes": [view.note for view in refined.views[1:]],
                                "cloud_mm": float(distances_mm.mean()), "seconds_per_view": seconds / (n - 1)})
    return records


def summarise(records: list[dict]) -> list[dict]:
    """One row per (object set, size, depth, n, row): accuracy, errors, refined share, harm, cloud, time."""
    groups: dict[tuple, list[dict]] = {}
    for record in records:
        key = (record["set"], record["size"], record["depth"], record["n"], record["row"])
        groups.setdefault(key, []).append(record)
    rows = []
    for (object_set, size, depth, n, row), items in groups.items():
        rotation = np.array([e[0] for r in items for e in r["errors"]])
        position = np.array([e[1] for r in items for e in r["errors"]])
        seed_rotation = np.array([e[0] for r in items for e in r["seed_errors"]])
        refined = np.array([f for r in items for f in r["refined"]])
        close = seed_rotation <= 30.0
        clouds = [r["cloud_mm"] for r in items if "cloud_mm" in r]
        times = [r["seconds_per_view"] for r in items if "seconds_per_view" in r]
        rows.append({
            "set": object_set, "size": size, "depth": depth, "n": n, "row": row, "estimates": len(items),
            "views": len(rotation), "rot_acc_5": float(np.mean(rotation < 5)),
            "rot_acc_15": float(np.mean(rotation < 15)), "rot_acc_30": float(np.mean(rotation < 30)),
            "median_rot_err_deg": float(np.median(rotation)),
            "median_position_err_cm": float(np.median(position)), "refined": float(refined.mean()),
            "worse_by_5": int(np.sum(refined & (rotation > seed_rotation + WORSE_DEG))),
            "seed_within_30": int(close.sum()),
            "rot_acc_15_seed_within_30": float(np.mean(rotation[close] < 15)) if close.any() else None,
            "median_rot_err_seed_within_30": float(np.median(rotation[close])) if close.any() else None,
            "cloud_mm": float(np.mean(clouds)) if clouds else None,
            "seconds_per_view": float(np.mean(times)) if times else None,
            "mask_iou_mean": float(np.mean([iou for r in items for iou in r["mask_iou"][:n]])),
            "mask_iou_worst": float(np.min([iou for r in items for iou in r["mask_iou"][:n]]))})
    return rows


def table(rows: list[dict]) -> str:
    """The markdown table of the summary rows."""
    def pct(value):
        return "" if value is None else f"{100 * value:.0f}"

    def num(value, digits=1):
        return "" if value is None else f"{value:.{digits}f}"
    lines = ["| set | size | depth | n | row | views | RotAcc@5 | @15 | @30 | median rot. (°) | median pos. (cm) | "
             "refined % | worse by 5° | seed ≤ 30°: @15 (views) | cloud (mm) | s / view | mask IoU mean / worst |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['set']} | {r['size']} | {r['depth']} | {r['n']} | {r['row']} | {r['views']} | "
                     f"{pct(r['rot_acc_5'])} | {pct(r['rot_acc_15'])} | {pct(r['rot_acc_30'])} | "
                     f"{num(r['median_rot_err_deg'])} | {num(r['median_position_err_cm'])} | {pct(r['refined'])} | "
                     f"{r['worse_by_5']} | {pct(r['rot_acc_15_seed_within_30'])} ({r['seed_within_30']}) | "
                     f"{num(r['cloud_mm'])} | {num(r['seconds_per_view'], 3)} | "
                     f"{r['mask_iou_mean']:.2f} / {r['mask_iou_worst']:.2f} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", type=int, default=4, help="scenes per object set and size")
    parser.add_argument("--model", default="", help="model of the diffusion rows (default: the embedded model)")
    parser.add_argument("--preset", choices=tuple(PRESETS), default="fast")
    parser.add_argument("--no-diffusion", action="store_true", help="only the rows that need no model")
    parser.add_argument("--seed", type=int, default=8080, help="first scene seed (each scene adds its index)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    predictor = None if args.no_diffusion else load_predictor(args.model)
    started = time.monotonic()
    scenes = [(object_set, spec, size, args.seed + index)
              for object_set, make in OBJECTS.items() for size in SIZES
              for index, spec in zip(range(args.scenes), make())]
    records = []
    for object_set, spec, size, seed in tqdm(scenes, desc="depth_refinement", unit="scene"):
        records += [{"set": object_set, **record} for record in measure_scene(spec, size, seed, predictor,
                                                                              args.preset)]
    rows = summarise(records)
    print("\n" + table(rows))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"scenes": args.scenes, "seed": args.seed, "model": args.model or "embedded",
                                    "preset": args.preset, "diffusion": not args.no_diffusion,
                                    "minutes": (time.monotonic() - started) / 60, "rows": rows,
                                    "records": records}, indent=1) + "\n")
    args.out.with_suffix(".md").write_text(table(rows) + "\n")
    print(f"wrote {args.out} and its table {args.out.with_suffix('.md').name} "
          f"({(time.monotonic() - started) / 60:.0f} min)")


if __name__ == "__main__":
    main()
