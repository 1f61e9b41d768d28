"""Solver accuracy on render-oracle scenes: RotAcc@15/30 per object set, view count and variant.

Usage (from the repository root): python -m bench.solver_oracle [--sets oracle demo symmetric] [--views 2 4 6]
       [--variants naive tr full] [--refine-steps 100] [--runner-up-steps 50] [--scenes-per-object 1]
Prints one line per (set, n, variant) and a JSON summary (idpose_core.metrics.aggregate) at the end.
The oracle uses ``ORACLE_SOLVER_SETTINGS`` (learning rates for its steeper error, probe batch 1).
``oracle_records`` is shared with ``bench/oracle_schedule.py``.
"""
from __future__ import annotations

import argparse
import json
import time
from collections.abc import Mapping, Sequence

import numpy as np
import torch

from idpose_core.cameras import spherical_to_c2w
from idpose_core.metrics import aggregate, pair_errors
from idpose_core.solver import SolverConfig, estimate_poses
from idpose_core.synthetic.render_oracle import ORACLE_SOLVER_SETTINGS, RenderOracle
from idpose_core.synthetic.scenes import (
    ObjectSpec,
    SceneRenderer,
    demo_objects,
    oracle_objects,
    random_camera_spheres,
    symmetric_objects,
)

SETS = {"oracle": oracle_objects, "demo": demo_objects, "symmetric": symmetric_objects}
RENDER_SIZE = 64  # the oracle only checks the input's shape; it answers from its own render grid


def scene_cameras(object_index: int, scene: int, count: int) -> np.ndarray:
    """The seeded random cameras (count, 3) of scene ``scene`` of object ``object_index``."""
    return random_camera_spheres(np.random.default_rng(1000 * scene + object_index), count)


def oracle_records(specs: Sequence[ObjectSpec], count: int, configs: Mapping[str, SolverConfig],
                   scenes_per_object: int = 1, log_label: str = "") -> dict[str, dict]:
    """Solve every scene with every config; per config the metric records and the flagged count.

    Each object gets ``scenes_per_object`` scenes of ``count`` random views; all configs see the same
    scenes. Returns ``{name: {"records": [{n, rot_err_deg, pos_err}, ...], "ambiguous": int}}``.
    """
    out = {name: {"records": [], "ambiguous": 0} for name in configs}
    total, done, start = len(specs) * scenes_per_object, 0, time.perf_counter()
    for index, spec in enumerate(specs):
        for scene in range(scenes_per_object):
            views = scene_cameras(index, scene, count)
            with SceneRenderer(spec, image_size=RENDER_SIZE) as renderer:
                renders = np.stack([renderer.render(*view)[0] for view in views])
            images = torch.from_numpy(renders).permute(0, 3, 1, 2).float() / 127.5 - 1.0
            oracle = RenderOracle(spec, views)
            cameras = spherical_to_c2w(views)
            for name, config in configs.items():
                result = estimate_poses(oracle, images, config)
                rot, pos = pair_errors(result.rel_poses, np.repeat(cameras[:1], count - 1, axis=0), cameras[1:])
                out[name]["records"] += [{"n": count, "rot_err_deg": float(r), "pos_err": float(p)}
                                         for r, p in zip(rot, pos)]
                out[name]["ambiguous"] += int(result.ambiguous.sum())
            done += 1
            if log_label:
                print(f"[{100 * done // total:3d}%] {log_label}: scene {done}/{total} "
                      f"({time.perf_counter() - start:.0f} s)", flush=True)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", nargs="+", default=["oracle", "demo"], choices=sorted(SETS))
    parser.add_argument("--views", nargs="+", type=int, default=[2, 4])
    parser.add_argument("--variants", nargs="+", default=["naive", "full"], choices=["naive", "tr", "full"])
    parser.add_argument("--refine-steps", type=int, default=100)
    parser.add_argument("--runner-up-steps", type=int, default=50)
    parser.add_argument("--scenes-per-object", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(1)

    summary = {}
    for set_name in args.sets:
        for count in args.views:
            configs = {variant: SolverConfig(**ORACLE_SOLVER_SETTINGS, variant=variant,
                                             refine_steps_per_view=args.refine_steps,
                                             runner_up_steps=args.runner_up_steps)
                       for variant in args.variants}
            start = time.perf_counter()
            solved = oracle_records(SETS[set_name](), count, configs, args.scenes_per_object)
            for variant, found in solved.items():
                figures = aggregate(found["records"])[str(count)]
                key = f"{set_name} n={count} {variant}"
                summary[key] = {**figures, "ambiguous": found["ambiguous"]}
                print(f"{key}: RotAcc@15 {figures['rot_acc_15']:.1%}  RotAcc@30 {figures['rot_acc_30']:.1%}  "
                      f"median {figures['median_rot_err_deg']:.2f} deg  ambiguous {found['ambiguous']}/"
                      f"{figures['pairs']}  ({time.perf_counter() - start:.0f} s for the set)", flush=True)
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
