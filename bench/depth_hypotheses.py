#!/usr/bin/env python3
"""Novel objects on a robot's path: poses from depth hypotheses and one verifier, against the diffusion path.

Fresh tabletop scenes of held-out objects (``catalogue.BENCH_HELDOUT``: never trained on, never ``random_urdfs``
900-999) under random lamps, seen by RGB-D cameras with exact and with active-stereo-like depth
(``tabletop.stereo_depth``). Pairs (n = 2) are drawn by the angle between the two cameras (``BINS``) for 20 cm
objects at 45-65 cm, and pooled for 8 cm objects at 25-35 cm and 60 cm objects at 0.9-1.2 m; sets of four views
(n = 4) have neighbours 30-60 deg apart. Every view's mask is the pipeline's own (depth cut and fallbacks).

Rows, each scoring the non-anchor views of the same scenes (each view one distinct pair with its anchor):
- ``diffusion (refine)``: the node as it was, the embedded default model (``--preset``) and ``depth_poses: refine``;
- ``diffusion + verifier``, ``registration``, ``gravity``: one source alone beside the diffusion hypotheses;
- ``all, no gravity`` / ``all``: registration, gravity (where the views carry it) and diffusion, one verifier;
- ``all + arm``: with each camera's pose from the arm, off by a kinematic and hand-eye error (0.5-1 deg, 2-5 mm
  per camera);
- ``all + arm, object moved``: the object turned 30-90 deg about the vertical between the two views (n = 2):
  the truth is the camera relative to the object, and ``moved flagged`` counts the views the result says moved.
Columns: RotAcc@5/@15/@30, median rotation (deg) and translation (cm) error, the share of views confident and
wrong (reliable, not ambiguous, over 30 deg off), seconds per estimate (the depth stage alone, and the model's),
and the model's forward samples per estimate (the depth sources add none).

    python bench/depth_hypotheses.py --pairs 6      # records in bench/results/depth_hypotheses/records.jsonl
    python bench/depth_hypotheses.py --summary      # the table (.json, .md) from the records
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

import numpy as np  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402
from tqdm import tqdm  # noqa: E402

from bench.result_files import result_path  # noqa: E402
from idpose_core.cameras import pinhole_camera_matrix  # noqa: E402
from idpose_core.depth_fusion import refine_with_depth  # noqa: E402
from idpose_core.metrics import rotation_angle_deg  # noqa: E402
from idpose_core.model_loading import load_predictor  # noqa: E402
from idpose_core.pipeline import PipelineSettings, estimate_view_poses, with_refinement  # noqa: E402
from idpose_core.pose_hypotheses import Source, VerificationSettings, verify_with_depth  # noqa: E402
from idpose_core.solver import SolverConfig  # noqa: E402
from idpose_core.synthetic.catalogue import BENCH_HELDOUT, heldout_objects  # noqa: E402
from idpose_core.synthetic.robot_views import with_arm_error  # noqa: E402
from idpose_core.synthetic.tabletop import (  # noqa: E402
    TabletopRenderer,
    challenge_camera,
    random_layout,
    stereo_depth,
)
from idpose_core.view_input import ViewInput  # noqa: E402

RECORDS = result_path("depth_hypotheses", "records.jsonl")
BINS = ((10.0, 45.0), (45.0, 90.0), (90.0, 135.0), (135.0, 160.0))  # deg between the cameras (n = 2)
# name -> (radius of the object's ball in m, camera distances in m, on a table)
SIZES = {"8 cm": (0.04, (0.25, 0.35), True), "20 cm": (0.1, (0.45, 0.65), True), "60 cm": (0.3, (0.9, 1.2), True)}
POLAR_DEG = (50.0, 85.0)  # the cameras' polar angles (deg from up)
NEIGHBOUR_DEG = (30.0, 60.0)  # n = 4: azimuth steps between neighbours
MOVED_DEG = (30.0, 90.0)  # the object's turn between views in the moved case
IMAGE_SIZE, FOV = 320, 60.0
SOURCES = {"diffusion + verifier": frozenset(), "registration": frozenset({Source.REGISTRATION}),
           "gravity": frozenset({Source.GRAVITY}), "all, no gravity": frozenset({Source.REGISTRATION}),
           "all": frozenset({Source.REGISTRATION, Source.GRAVITY}),
           "all + arm": frozenset(Source)}
NO_GRAVITY = {"all, no gravity"}


def pair_spheres(rng: np.random.Generator, low: float, high: float, distances: tuple[float, float]) -> np.ndarray:
    """Two cameras (2, 3) = (polar, azimuth, radius) whose viewing directions are ``low``-``high`` deg apart."""
    while True:
        separation = math.radians(rng.uniform(low, high))
        first, second = np.radians(rng.uniform(*POLAR_DEG, 2))
        cosine = (math.cos(separation) - math.cos(first) * math.cos(second)) / (math.sin(first) * math.sin(second))
        if abs(cosine) <= 1.0:
            azimuth = rng.uniform(0.0, 2.0 * math.pi)
            turn = math.acos(cosine) * rng.choice([-1.0, 1.0])
            return np.array([[first, azimuth, rng.uniform(*distances)],
                             [second, azimuth + turn, rng.uniform(*distances)]])


def chain_spheres(rng: np.random.Generator, count: int, distances: tuple[float, float]) -> np.ndarray:
    """``count`` cameras going round the object, neighbours ``NEIGHBOUR_DEG`` apart in azimuth."""
    azimuths = rng.uniform(0.0, 2.0 * math.pi) + np.cumsum([0.0, *np.radians(rng.uniform(*NEIGHBOUR_DEG,
                                                                                         count - 1))])
    return np.array([[math.radians(rng.uniform(*POLAR_DEG)), a, rng.uniform(*distances)] for a in azimuths])


def render(spec, spheres: np.ndarray, radius: float, table: bool, rng: np.random.Generator, moved_deg: float = 0.0):
    """Frames of the cameras at ``spheres`` and the cameras (N, 4, 4); with ``moved_deg`` the object is turned by
    that much about the vertical before the last view is taken."""
    layout = random_layout(spec, rng, behind_azimuth=float(spheres[0, 1]), target_radius=radius, table=table)
    cameras = np.stack([challenge_camera(sphere) for sphere in spheres])
    with TabletopRenderer(layout, IMAGE_SIZE, FOV, far=6.0) as renderer:
        frames = [renderer.render(camera) for camera in cameras[:-1]]
    if moved_deg:
        target = dataclasses.replace(layout.target, yaw_deg=layout.target.yaw_deg + moved_deg)
        layout = dataclasses.replace(layout, target=target)
    with TabletopRenderer(layout, IMAGE_SIZE, FOV, far=6.0) as renderer:
        frames.append(renderer.render(cameras[-1]))
    return frames, cameras


def errors(poses: np.ndarray, truth: np.ndarray) -> list[tuple[float, float]]:
    """(rotation error deg, position error cm) of every non-anchor view."""
    return [(float(rotation_angle_deg(poses[k, :3, :3], truth[k, :3, :3])),
             100.0 * float(np.linalg.norm(poses[k, :3, 3] - truth[k, :3, 3]))) for k in range(1, len(poses))]


def measure(predictor, preset: str, spec, case: dict, rng: np.random.Generator) -> list[dict]:
    """Every row's record of one scene: ``case`` gives its size, cameras, depth kind and whether it moves."""
    radius, distances, table = SIZES[case["size"]]
    moved = case.get("moved_deg", 0.0)
    frames, cameras = render(spec, np.asarray(case["spheres"]), radius, table, rng, moved)
    intrinsics = pinhole_camera_matrix(IMAGE_SIZE, IMAGE_SIZE, FOV)
    truth = np.linalg.inv(cameras[0]) @ cameras
    if moved:  # the last camera relative to the object, which turned by ``moved`` about the vertical
        turn = np.eye(4)
        turn[:3, :3] = Rotation.from_euler("z", -moved, degrees=True).as_matrix()
        truth[-1] = np.linalg.inv(cameras[0]) @ turn @ cameras[-1]
    arm = [with_arm_error(camera, rng) for camera in cameras]
    depths = [frame.depth if case["depth"] == "exact" else stereo_depth(frame.depth, rng) for frame in frames]
    ups = [camera[:3, :3].T @ [0.0, 0.0, 1.0] for camera in cameras]
    views = [ViewInput(rgb=f.rgb, depth=d, intrinsics=intrinsics, gravity_up=up, camera_pose=pose)
             for f, d, up, pose in zip(frames, depths, ups, arm)]
    settings = PipelineSettings(SolverConfig.preset(preset), depth_refinement=False)
    start = time.perf_counter()
    diffusion = estimate_view_poses(predictor, views, settings)
    model_seconds = time.perf_counter() - start
    base = {**case, "object": spec.name, "model_seconds": model_seconds,
            "forward_samples": diffusion.solver_result.forward_samples}
    records = []
    rows = {"diffusion (refine)": None, **SOURCES} if not moved else {"all + arm, object moved": frozenset(Source)}
    for row, sources in rows.items():
        start = time.perf_counter()
        if sources is None:
            depth = refine_with_depth(views, diffusion.masks, diffusion.poses, 0.005)
        else:
            scene_views = ([dataclasses.replace(v, gravity_up=None) for v in views] if row in NO_GRAVITY else views)
            depth = verify_with_depth(scene_views, diffusion.masks, diffusion.poses, diffusion.runner_up_poses, 0.005,
                                      VerificationSettings(sources=sources))
        seconds = time.perf_counter() - start
        poses = diffusion.poses if depth is None else depth.poses
        reports = diffusion.views if depth is None else [
            with_refinement(report, refinement, settings.min_mask_confidence)
            for report, refinement in zip(diffusion.views, depth.views)]
        records.append({**base, "row": row, "errors": errors(poses, truth), "depth_seconds": seconds,
                        "reliable": [r.reliable for r in reports[1:]],
                        "sources": [r.refinement.source if r.refinement else "diffusion" for r in reports[1:]],
                        "moved_flagged": [bool(r.refinement and r.refinement.object_moved) for r in reports[1:]]})
    return records


def cases(pairs: int, chains: int, rng: np.random.Generator) -> list[dict]:
    """The scenes: ``pairs`` per separation bin and depth (20 cm), a few 8 cm and 60 cm pairs, moved pairs, and
    ``chains`` sets of four views per depth."""
    found = []
    for depth in ("exact", "stereo"):
        for index, (low, high) in enumerate(BINS):
            found += [{"n": 2, "size": "20 cm", "depth": depth, "bin": index,
                       "spheres": pair_spheres(rng, low, high, SIZES["20 cm"][1]).tolist()} for _ in range(pairs)]
        for size in ("8 cm", "60 cm"):
            found += [{"n": 2, "size": size, "depth": depth, "bin": int(rng.integers(0, 3)), "spheres": None}
                      for _ in range(max(1, pairs // 2))]
        found += [{"n": 4, "size": "20 cm", "depth": depth, "bin": -1,
                   "spheres": chain_spheres(rng, 4, SIZES["20 cm"][1]).tolist()} for _ in range(chains)]
        found += [{"n": 2, "size": "20 cm", "depth": depth, "bin": int(rng.integers(0, 2)), "spheres": None,
                   "moved_deg": float(rng.uniform(*MOVED_DEG) * rng.choice([-1, 1]))} for _ in range(pairs)]
    for case in found:
        if case["spheres"] is None:
            low, high = BINS[case["bin"]]
            case["spheres"] = pair_spheres(rng, low, high, SIZES[case["size"]][1]).tolist()
    return found


def summarise(records: list[dict]) -> list[dict]:
    """One row per (group, row): accuracy, errors, confident-and-wrong share, time, model work."""
    groups: dict[tuple, list[dict]] = {}
    for record in records:
        if record["n"] == 4:
            group = "n = 4, neighbours 30-60 deg"
        elif record["size"] != "20 cm":
            group = f"n = 2, {record['size']}, 10-135 deg"
        else:
            low, high = BINS[record["bin"]]
            group = f"n = 2, 20 cm, {low:.0f}-{high:.0f} deg"
        groups.setdefault((record["depth"], group, record["row"]), []).append(record)
    rows = []
    for (depth, group, row), items in sorted(groups.items()):
        rotation = np.array([e[0] for r in items for e in r["errors"]])
        position = np.array([e[1] for r in items for e in r["errors"]])
        reliable = np.array([f for r in items for f in r["reliable"]])
        moved = [f for r in items if r.get("moved_deg") for f in r["moved_flagged"]]
        rows.append({"depth": depth, "group": group, "row": row, "views": len(rotation),
                     "distinct_pairs": len({(r["object"], json.dumps(r["spheres"]), k) for r in items
                                            for k in range(r["n"] - 1)}),
                     "rot_acc_5": float(np.mean(rotation < 5)), "rot_acc_15": float(np.mean(rotation < 15)),
                     "rot_acc_30": float(np.mean(rotation < 30)), "median_rot_err_deg": float(np.median(rotation)),
                     "median_position_err_cm": float(np.median(position)),
                     "confident_wrong": float(np.mean(reliable & (rotation > 30))),
                     "reliable": float(np.mean(reliable)),
                     "moved_flagged": float(np.mean(moved)) if moved else None,
                     "depth_seconds_per_view": float(np.mean([r["depth_seconds"] / (r["n"] - 1) for r in items])),
                     "model_seconds": float(np.mean([r["model_seconds"] for r in items])),
                     "forward_samples": float(np.mean([r["forward_samples"] for r in items]))})
    return rows


def table(rows: list[dict]) -> str:
    """The summary as Markdown."""
    lines = ["| depth | scenes | row | views | RotAcc@5 | @15 | @30 | median deg | median cm | confident & wrong | "
             "moved flagged | depth s/view | model s | forward samples |", "|" + "---|" * 14]
    for r in rows:
        moved = "" if r["moved_flagged"] is None else f"{100 * r['moved_flagged']:.0f} %"
        lines.append(f"| {r['depth']} | {r['group']} | {r['row']} | {r['views']} | {100 * r['rot_acc_5']:.0f} | "
                     f"{100 * r['rot_acc_15']:.0f} | {100 * r['rot_acc_30']:.0f} | {r['median_rot_err_deg']:.1f} | "
                     f"{r['median_position_err_cm']:.1f} | {100 * r['confident_wrong']:.0f} % | {moved} | "
                     f"{r['depth_seconds_per_view']:.1f} | {r['model_seconds']:.1f} | {r['forward_samples']:.0f} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=6, help="pairs per separation bin and depth (20 cm objects)")
    parser.add_argument("--chains", type=int, default=4, help="sets of four views per depth")
    parser.add_argument("--seed", type=int, default=5150)
    parser.add_argument("--model", default="", help="the diffusion model (default: the embedded model)")
    parser.add_argument("--preset", default="fast")
    parser.add_argument("--summary", action="store_true", help="only summarise the records")
    args = parser.parse_args()
    if not args.summary:
        rng = np.random.default_rng(args.seed)
        objects = heldout_objects(*BENCH_HELDOUT)
        todo = cases(args.pairs, args.chains, rng)
        done = sum(1 for _ in RECORDS.open()) if RECORDS.exists() else 0
        finished = {json.loads(line)["case"] for line in RECORDS.open()} if done else set()
        predictor = load_predictor(args.model)
        with RECORDS.open("a") as out:
            for index, case in enumerate(tqdm(todo, desc="scenes")):
                if index in finished:
                    continue
                spec = objects[int(np.random.default_rng(args.seed + index).integers(len(objects)))]
                for record in measure(predictor, args.preset, spec, case, np.random.default_rng(args.seed + index)):
                    out.write(json.dumps({**record, "case": index}) + "\n")
                out.flush()
    rows = summarise([json.loads(line) for line in RECORDS.open()])
    result_path("depth_hypotheses").write_text(json.dumps(rows, indent=1))
    result_path("depth_hypotheses", "depth_hypotheses.md").write_text(table(rows) + "\n")
    print(table(rows))


if __name__ == "__main__":
    main()
