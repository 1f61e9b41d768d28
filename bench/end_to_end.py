"""End-to-end seconds per estimate with the small demo model on this CPU, n = 2 and 4.

The model comes through ``load_predictor("")`` (the embedded demo model, ``idpose_core/assets/
demo_model``; loading timed once), or ``--model-dir``. Scenes: fresh random cameras (seeds no
training run used) around the demo objects, rendered at 256 px with their alpha masks. Each
estimate is the pipeline the node runs: ``estimate_view_poses`` (preprocess -> solve -> anchor-frame
poses) under a solver preset plus the model's own ``solver_defaults`` (its timesteps). Rotation
errors are reported beside the times.

Usage (from the repository root): python -m bench.end_to_end [--views 2 4] [--presets default fast]
       [--scenes 2] [--threads 1] [--model-dir FOLDER]
Writes bench/results/end_to_end/end_to_end.json.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time

import numpy as np
import torch

from bench.result_files import result_path
from idpose_core.cameras import spherical_to_c2w
from idpose_core.demo_model import DemoPredictor
from idpose_core.metrics import pair_errors
from idpose_core.model_loading import load_predictor
from idpose_core.pipeline import PipelineSettings, ViewInput, estimate_view_poses
from idpose_core.solver import SolverConfig
from idpose_core.synthetic.scenes import CAMERA_RADIUS, SceneRenderer, demo_objects, random_camera_spheres

IMAGE_SIZE = 256
SCENE_SEED = 4242  # the demo model's training and accuracy runs use other seeds


def render_scene(scene: int, count: int) -> tuple[str, np.ndarray, list[np.ndarray], list[np.ndarray]]:
    """Object name, cameras (count, 3), RGB renders and alpha masks of scene ``scene``."""
    specs = demo_objects()
    spec = specs[scene % len(specs)]
    cameras = random_camera_spheres(np.random.default_rng(SCENE_SEED + 100 * count + scene), count)
    with SceneRenderer(spec, image_size=IMAGE_SIZE) as renderer:
        renders = [renderer.render(*camera) for camera in cameras]
    return spec.name, cameras, [rgb for rgb, _ in renders], [mask.astype(np.uint8) * 255 for _, mask in renders]


def demo_predictor(model_dir: str) -> tuple[DemoPredictor, str]:
    """The model to time and where its weights come from: a given folder or the embedded model."""
    if model_dir:
        return DemoPredictor.from_pretrained(model_dir), f"folder {model_dir}"
    return load_predictor("", device="cpu"), "embedded"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", nargs="+", type=int, default=[2, 4])
    parser.add_argument("--presets", nargs="+", default=["default", "fast"])
    parser.add_argument("--scenes", type=int, default=2, help="scenes per view count (one demo object each)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (tiny tensors: 1 is the quickest)")
    parser.add_argument("--model-dir", default="", help="a demo-model folder instead of the embedded one")
    args = parser.parse_args()
    out = result_path("end_to_end")
    out.parent.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(args.threads)

    start = time.perf_counter()
    predictor, weights = demo_predictor(args.model_dir)
    load_seconds = time.perf_counter() - start
    recommended = dict(predictor.solver_defaults)
    print(f"loaded the demo model ({weights}) in {load_seconds:.2f} s; its recommended solver settings "
          f"(the pipeline applies them): {recommended}")

    rows = []
    load_before = os.getloadavg()[0]
    for count in args.views:
        for preset in args.presets:
            config = SolverConfig.preset(preset)
            runs = []
            for scene in range(args.scenes):
                name, cameras, rgbs, alphas = render_scene(scene, count)
                start = time.perf_counter()
                views = [ViewInput(rgb, alpha) for rgb, alpha in zip(rgbs, alphas)]
                # relative poses are scored: the anchor's polar angle stays unknown, as in the paper's grid
                result = estimate_view_poses(predictor, views, PipelineSettings(config, CAMERA_RADIUS))
                seconds = time.perf_counter() - start
                c2w = spherical_to_c2w(cameras)
                solved = result.solver_result
                rot, _ = pair_errors(solved.rel_poses, np.repeat(c2w[:1], count - 1, axis=0), c2w[1:])
                runs.append({"object": name, "seconds": seconds, "stage_seconds": solved.stage_seconds,
                             "forward_samples": solved.forward_samples, "backward_samples": solved.backward_samples,
                             "rot_err_deg": [float(r) for r in rot]})
                print(f"n={count} {preset:<8} {name:<11} {seconds:7.1f} s  rotation errors "
                      + " ".join(f"{r:5.1f}" for r in rot), flush=True)
            errors = np.concatenate([run["rot_err_deg"] for run in runs])
            rows.append({"n": count, "preset": preset, "runs": runs,
                         "median_seconds": statistics.median(run["seconds"] for run in runs),
                         "rot_acc_15": float(np.mean(errors < 15)), "rot_acc_30": float(np.mean(errors < 30)),
                         "pairs": int(errors.size)})

    report = {"status": "measured", "weights": weights, "load_seconds": load_seconds,
              "threads": args.threads, "image_size": IMAGE_SIZE, "recommended_solver_settings": recommended,
              "load_average": [load_before, os.getloadavg()[0]], "rows": rows}
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"\nweights: {weights}\n{'n':>2} {'preset':<8}{'median s':>10}{'RotAcc@15':>11}{'@30':>7}{'pairs':>7}")
    for row in rows:
        print(f"{row['n']:>2} {row['preset']:<8}{row['median_seconds']:>10.1f}{row['rot_acc_15']:>11.0%}"
              f"{row['rot_acc_30']:>7.0%}{row['pairs']:>7}")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
