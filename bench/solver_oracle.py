"""Solver accuracy on render-oracle scenes: RotAcc@15/30 per object set, view count and variant.

Usage (from the repository root): PYTHONPATH=. python bench/solver_oracle.py [--sets oracle demo symmetric] [--views 2 4 6]
       [--variants naive tr full] [--refine-steps 100] [--runner-up-steps 50] [--scenes-per-object 1]
Prints one line per (set, n, variant) and a JSON summary (idpose_core.metrics.aggregate) at the end.
The oracle uses ``ORACLE_SOLVER_SETTINGS`` (learning rates for its steeper error, probe batch 1).
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from idpose_core.cameras import spherical_to_c2w
from idpose_core.metrics import aggregate, pair_errors
from idpose_core.solver import SolverConfig, estimate_poses
from idpose_core.synthetic.render_oracle import ORACLE_SOLVER_SETTINGS, RenderOracle
from idpose_core.synthetic.scenes import (SceneRenderer, demo_objects, oracle_objects, random_camera_spheres,
                                          symmetric_objects)

SETS = {"oracle": oracle_objects, "demo": demo_objects, "symmetric": symmetric_objects}


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
            for variant in args.variants:
                config = SolverConfig(**ORACLE_SOLVER_SETTINGS, variant=variant,
                                      refine_steps_per_view=args.refine_steps,
                                      runner_up_steps=args.runner_up_steps)
                records, flagged, start = [], 0, time.perf_counter()
                for index, spec in enumerate(SETS[set_name]()):
                    for scene in range(args.scenes_per_object):
                        views = random_camera_spheres(np.random.default_rng(1000 * scene + index), count)
                        with SceneRenderer(spec, image_size=64) as renderer:
                            renders = np.stack([renderer.render(*view)[0] for view in views])
                        images = torch.from_numpy(renders).permute(0, 3, 1, 2).float() / 127.5 - 1.0
                        result = estimate_poses(RenderOracle(spec, views), images, config)
                        cameras = spherical_to_c2w(views)
                        rot, pos = pair_errors(result.rel_poses, np.repeat(cameras[:1], count - 1, axis=0),
                                               cameras[1:])
                        records += [{"n": count, "rot_err_deg": r, "pos_err": p} for r, p in zip(rot, pos)]
                        flagged += int(result.ambiguous.sum())
                figures = aggregate(records)[str(count)]
                key = f"{set_name} n={count} {variant}"
                summary[key] = {**figures, "ambiguous": flagged}
                print(f"{key}: RotAcc@15 {figures['rot_acc_15']:.1%}  RotAcc@30 {figures['rot_acc_30']:.1%}  "
                      f"median {figures['median_rot_err_deg']:.2f} deg  ambiguous {flagged}/{figures['pairs']}  "
                      f"({time.perf_counter() - start:.0f} s)", flush=True)
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
