"""How far bfloat16 moves what the solver sees: noise errors and pose gradients vs float32, same samples.

Full-size Zero-1-to-3 architecture with random weights (seed 0), 256 px views, as ``step_cost.py``
builds it, once in float32 and once in bfloat16 (``load_predictor``'s precisions). On identical views,
poses, timesteps and noises: the per-sample noise errors of one probe batch (16 samples, t = 200,
forward only) and the pose gradients of single-sample steps (t in [200, 210]). Random weights test the
arithmetic, not a trained model's landscape: the demo model's accuracy in bfloat16 is
``bench/demo_model_accuracy.py --precision bfloat16``.

Usage: python bench/precision_fidelity.py [--steps 8] [--threads 2] [--config full|tiny]
Writes bench/results/precision_fidelity/precision_fidelity.json and prints the figures.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from bench.result_files import result_path  # noqa: E402
from idpose_core.model_loading import PRECISIONS  # noqa: E402
from idpose_core.zero123 import Zero123Config, Zero123Predictor  # noqa: E402

PROBE_BATCH, PROBE_T, STEP_T = 16, 200, (200, 210)
OUT = result_path("precision_fidelity")


def samples(count_probe: int, count_steps: int, noise_shape: tuple, seed: int = 0) -> dict:
    """The shared inputs: probe noises and poses, step poses, timesteps and noises."""
    generator = torch.Generator().manual_seed(seed)
    return {
        "probe_pose": (torch.rand(count_probe, 3, generator=generator) - 0.5) * torch.tensor([2.0, 6.28, 0.0]),
        "probe_noise": torch.randn(count_probe, *noise_shape, generator=generator),
        "step_pose": (torch.rand(count_steps, 3, generator=generator) - 0.5) * torch.tensor([2.0, 6.28, 0.0]),
        "step_t": torch.randint(STEP_T[0], STEP_T[1] + 1, (count_steps,), generator=generator),
        "step_noise": torch.randn(count_steps, *noise_shape, generator=generator),
    }


def evaluate(precision: str, config: Zero123Config, images: torch.Tensor, steps: int) -> dict:
    """Probe errors (16,) and step gradients (steps, 3) of one precision."""
    predictor = Zero123Predictor.random(config, seed=0, device="cpu", dtype=PRECISIONS[precision])
    views = predictor.encode(images)
    inputs = samples(PROBE_BATCH, steps, views.noise_shape)
    zero, one = torch.zeros(PROBE_BATCH, dtype=torch.long), torch.ones(PROBE_BATCH, dtype=torch.long)
    with torch.no_grad():
        probe = predictor.noise_error(views, zero, one, inputs["probe_pose"], torch.full((PROBE_BATCH,), PROBE_T),
                                      inputs["probe_noise"])
    gradients, step_errors = [], []
    for k in range(steps):
        pose = inputs["step_pose"][k:k + 1].clone().requires_grad_(True)
        error = predictor.noise_error(views, zero[:1], one[:1], pose, inputs["step_t"][k:k + 1],
                                      inputs["step_noise"][k:k + 1])
        error.sum().backward()
        gradients.append(pose.grad[0])
        step_errors.append(error.detach()[0])
        print(f"  {precision}: step {k + 1}/{steps}", flush=True)
    return {"probe_errors": probe.float(), "step_errors": torch.stack(step_errors).float(),
            "gradients": torch.stack(gradients).float()}


def compare(reference: dict, other: dict) -> dict:
    """Relative error differences, gradient cosines and norm ratios, and whether the probe ranking holds."""
    def relative(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        return ((a - b).abs() / a.abs()).max()

    ref_grad, grad = reference["gradients"], other["gradients"]
    cosine = torch.nn.functional.cosine_similarity(ref_grad, grad, dim=1)
    norm_ratio = grad.norm(dim=1) / ref_grad.norm(dim=1)
    return {
        "probe_error_max_relative_difference": float(relative(reference["probe_errors"], other["probe_errors"])),
        "step_error_max_relative_difference": float(relative(reference["step_errors"], other["step_errors"])),
        "probe_best_sample_same": bool(reference["probe_errors"].argmin() == other["probe_errors"].argmin()),
        "gradient_cosine_min": float(cosine.min()), "gradient_cosine_median": float(cosine.median()),
        "gradient_norm_ratio_min": float(norm_ratio.min()), "gradient_norm_ratio_max": float(norm_ratio.max()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=8, help="differentiated single-sample steps compared")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--config", choices=("full", "tiny"), default="full", help="tiny: smoke test only")
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    config = Zero123Config.full() if args.config == "full" else Zero123Config.tiny()
    images = torch.rand(2, 3, args.size, args.size, generator=torch.Generator().manual_seed(0)) * 2 - 1
    figures = {precision: evaluate(precision, config, images, args.steps) for precision in ("float32", "bfloat16")}
    result = {"setup": {"config": args.config, "image_size": args.size, "weights": "random", "probe_batch": PROBE_BATCH,
                        "probe_t": PROBE_T, "step_t": STEP_T, "steps": args.steps, "threads": args.threads},
              "bfloat16_vs_float32": compare(figures["float32"], figures["bfloat16"])}
    for name, value in result["bfloat16_vs_float32"].items():
        print(f"{name:<40} {value}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
