"""What one ID-Pose step costs on this CPU: this project's way vs the official implementation's way.

Full-size Zero-1-to-3 architecture with random weights (the cost does not depend on the values),
256 px images. The official way runs in float32, as its code does; ours in each of ``--precisions``
(``load_predictor``'s precision: the UNet in that dtype; VAE, CLIP and cc_projection in float32). Each
measurement runs in its own subprocess, so its peak memory is its own: ``peak_gb`` over the whole
process (``ru_maxrss``, including building the model: a bfloat16 model is built in float32 first),
``run_peak_gb`` from the end of building to the end of the measurement (Linux VmHWM, reset in between:
weights + cached views + activations + gradients). The kinds alternate in one run.

What is measured (one "step" = what the solvers do per refinement iteration):
- ours_step: the solver's refinement step. Views were encoded once beforehand (VAE + CLIP, not
  timed); one ``noise_error`` sample (one direction, fresh noise, t in [200, 210]) forward and
  backward to the pose only (all weights frozen, no gradient checkpointing).
- official_step: the same modules run as the official code runs a step: VAE-encode the reference
  (mode) and the target (sample x 0.18215) and CLIP-encode the reference again, then the UNet
  forward + backward with weight gradients enabled on the UNet and cc_projection and gradient
  checkpointing on the UNet; an EMA copy of the UNet is held in memory as the LDM model object does.
- ours_adjust: one step of the exploration's candidate adjustment as the solver runs it for n = 2
  (``exploration.adjust``, 20 candidates, default ``grad_batch``): seconds per differentiated sample
  in ``parts["per_sample"]``; the solver's adjust steps cost this, not a batch-1 step.
- ours_probe / official_probe: one exploration probe = one pose candidate in one direction under
  16 noise samples at t = 200, forward only (no grad) - ours from cached views, official
  re-encoding 16 reference + 16 target images through the VAE and 16 references through CLIP.
Steps: one untimed warm-up, then ``--repeats`` timed steps (mean). Probes: one timed probe.
Wall seconds and process CPU seconds (all threads) are both kept: on a shared machine the CPU
time is the steadier figure; each measurement also records the 1-minute load average.

Usage: python bench/step_cost.py [--alternations 2] [--repeats 2] [--threads 2] [--config full|tiny]
       [--precisions float32 bfloat16]
Writes bench/results/step_cost/step_cost.json and prints the figures and the ratios.
"""
from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from idpose_core.model_loading import PRECISIONS  # noqa: E402
from idpose_core.solver import SolverConfig  # noqa: E402
from idpose_core.solver.context import SolverContext, diffusion_step  # noqa: E402
from idpose_core.solver.exploration import adjust, candidate_grid  # noqa: E402
from idpose_core.zero123 import Zero123Config, Zero123Predictor  # noqa: E402

OFFICIAL_KINDS = ("official_step", "official_probe")
OURS_KINDS = ("ours_step", "ours_adjust", "ours_probe")
DEFAULTS = SolverConfig()  # steps and probes are timed as the solver runs them by default
ADJUSTED_CANDIDATES = len(candidate_grid(DEFAULTS)) // 2  # the better half of the grid, one non-anchor view
PROBE_BATCH = DEFAULTS.probe_batch


def probe_step(predictor) -> int:
    """The probes' diffusion step for this predictor's schedule."""
    return diffusion_step(DEFAULTS.probe_t, predictor.num_train_timesteps)


def refinement_step(predictor, generator: torch.Generator) -> torch.Tensor:
    """A refinement step's diffusion step (1,), drawn from the solver's range for this predictor's schedule."""
    low, high = (diffusion_step(fraction, predictor.num_train_timesteps) for fraction in DEFAULTS.refine_t_range)
    return torch.randint(low, high + 1, (1,), generator=generator)


def main() -> None:
    args = parse_args()
    if args.child:
        print("RESULT " + json.dumps(measure(args.child, args)), flush=True)
        return
    kinds = measured_kinds(args.precisions)
    runs = {kind: [] for kind in kinds}
    load_before = os.getloadavg()
    total = args.alternations * len(kinds)
    for alternation in range(args.alternations):
        for kind in kinds:
            done = alternation * len(kinds) + kinds.index(kind)
            print(f"[{100 * done // total:3d}%] alternation {alternation + 1}/{args.alternations}: {kind} ...",
                  flush=True)
            result = run_child(kind, args)
            runs[kind].append(result)
            print(f"       {kind}: {result['seconds']:.2f} s ({result['cpu_seconds']:.2f} CPU s), peak "
                  f"{result['peak_gb']:.2f} GB (after building {result['built_gb']:.2f} GB; while running "
                  f"{result['run_peak_gb']:.2f} GB), "
                  f"load {result['load_average']:.1f}", flush=True)
    report = summarise(runs, args, load_before)
    print_summary(report)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"wrote {out}")


def measured_kinds(precisions: list[str]) -> list[str]:
    """The official kinds, then ours in every precision: ``ours_step@bfloat16`` etc."""
    return [*OFFICIAL_KINDS, *(f"{kind}@{precision}" for precision in precisions for kind in OURS_KINDS)]


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--alternations", type=int, default=2, help="rounds of the four kinds, interleaved")
    parser.add_argument("--repeats", type=int, default=2, help="timed steps per step measurement")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--size", type=int, default=256, help="image side in pixels")
    parser.add_argument("--config", choices=("full", "tiny"), default="full", help="tiny: smoke test only")
    parser.add_argument("--precisions", nargs="+", choices=("float32", "bfloat16"), default=["float32", "bfloat16"],
                        help="our side's precisions (the official way runs in float32)")
    parser.add_argument("--out", default=str(ROOT / "bench" / "results" / "step_cost.json"))
    parser.add_argument("--child", help=argparse.SUPPRESS)
    return parser.parse_args()


def run_child(kind: str, args: argparse.Namespace) -> dict:
    """One measurement in a fresh interpreter; its stdout carries one RESULT line."""
    command = [sys.executable, str(Path(__file__).resolve()), "--child", kind, "--repeats", str(args.repeats),
               "--threads", str(args.threads), "--size", str(args.size), "--config", args.config]
    completed = subprocess.run(command, cwd=ROOT, capture_output=True, text=True,
                               env={**os.environ, "PYTHONPATH": str(ROOT)})
    lines = [line for line in completed.stdout.splitlines() if line.startswith("RESULT ")]
    if completed.returncode != 0 or not lines:
        raise RuntimeError(f"{kind} measurement failed:\n{completed.stderr[-3000:]}")
    return json.loads(lines[-1][len("RESULT "):])


def measure(kind: str, args: argparse.Namespace) -> dict:
    """Build the model, then time ``kind``; returns seconds and memory of this process."""
    torch.set_num_threads(args.threads)
    kind, _, precision = kind.partition("@")
    config = Zero123Config.full() if args.config == "full" else Zero123Config.tiny()
    predictor = Zero123Predictor.random(config, seed=0, device="cpu", dtype=PRECISIONS[precision or "float32"])
    generator = torch.Generator().manual_seed(0)
    images = torch.rand(2, 3, args.size, args.size, generator=generator) * 2 - 1
    official = kind.startswith("official")
    if official:
        ema = prepare_official(predictor)
    else:
        views = predictor.encode(images)
    built_gb = current_rss_gb()
    reset_peak_rss()
    run = {
        "ours_step": lambda: ours_step(predictor, views, generator),
        "ours_adjust": lambda: ours_adjust(predictor, views),
        "ours_probe": lambda: ours_probe(predictor, views, generator),
        "official_step": lambda: official_step(predictor, images, generator),
        "official_probe": lambda: official_probe(predictor, images, generator),
    }[kind]
    timings = []
    repeats = args.repeats if kind.endswith("step") else 1
    if kind.endswith(("step", "adjust")):
        run()  # warm-up
    for _ in range(repeats):
        cpu_start = time.process_time()
        timings.append(run())
        timings[-1]["cpu"] = time.process_time() - cpu_start
    run_peak_gb = peak_rss_since_reset_gb()
    result = {
        "seconds": statistics.mean(t["total"] for t in timings),
        "cpu_seconds": statistics.mean(t["cpu"] for t in timings),
        "load_average": os.getloadavg()[0],
        "parts": {part: statistics.mean(t[part] for t in timings) for part in timings[0]},
        "repeats": repeats,
        "built_gb": built_gb,
        "run_peak_gb": run_peak_gb,
        "peak_gb": max(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2, run_peak_gb),
    }
    if official:
        result["ema_parameters"] = sum(p.numel() for p in ema.parameters())
    return result


def prepare_official(predictor):
    """The official training-style model state: UNet and cc_projection trainable, checkpointed, plus EMA."""
    modules = predictor.modules
    modules.unet.requires_grad_(True)
    modules.cc_projection.requires_grad_(True)
    modules.unet.enable_gradient_checkpointing()
    return copy.deepcopy(modules.unet).requires_grad_(False)


def ours_step(predictor, views, generator) -> dict:
    """One refinement step as the solver runs it: 1 sample, pose-only gradient, cached views."""
    start = time.perf_counter()
    pose = torch.tensor([[0.2, 1.0, 0.0]], requires_grad=True)
    t = refinement_step(predictor, generator)
    noise = torch.randn(1, *views.noise_shape, generator=generator)
    predictor.noise_error(views, torch.tensor([0]), torch.tensor([1]), pose, t, noise).sum().backward()
    return {"total": time.perf_counter() - start}


def ours_adjust(predictor, views) -> dict:
    """One adjust step of the solver's exploration: the better half of the default grid, forward direction, chunks
    of grad_batch."""
    config = dataclasses.replace(DEFAULTS, adjust_steps=1)
    context = SolverContext(predictor, views, config)
    starts = torch.tensor([[0.2, 0.3 * k, 0.0] for k in range(ADJUSTED_CANDIDATES)])
    start = time.perf_counter()
    adjust(context, starts, torch.ones(ADJUSTED_CANDIDATES, dtype=torch.long))
    total = time.perf_counter() - start
    return {"total": total, "per_sample": total / context.backward_samples}


def official_encode(predictor, ref_images, tgt_images, generator):
    """Per-step conditioning the official way: VAE on both images, CLIP on the reference."""
    modules = predictor.modules
    with torch.no_grad():
        ref_latents = modules.vae.encode(ref_images).latent_dist.mode()
        tgt_latents = modules.vae.encode(tgt_images).latent_dist.sample(generator) * modules.vae.config.scaling_factor
        embeds = modules.image_encoder(pixel_values=predictor.clip_pixels(ref_images)).image_embeds
    return ref_latents, tgt_latents, embeds


def official_step(predictor, images, generator) -> dict:
    """One official refinement step: re-encode, then UNet forward + backward with weight gradients."""
    start = time.perf_counter()
    ref_latents, tgt_latents, embeds = official_encode(predictor, images[:1], images[1:], generator)
    encoded = time.perf_counter()
    pose = torch.tensor([[0.2, 1.0, 0.0]], requires_grad=True)
    t = refinement_step(predictor, generator)
    noise = torch.randn(tgt_latents.shape, generator=generator)
    noisy = predictor.modules.scheduler.add_noise(tgt_latents, noise, t)
    eps = predictor.predict_noise(noisy, ref_latents, t, predictor.pose_tokens(embeds, pose))
    (eps - noise).square().mean().backward()
    end = time.perf_counter()
    return {"total": end - start, "encode": encoded - start, "unet_forward_backward": end - encoded}


def ours_probe(predictor, views, generator) -> dict:
    """One probe: one candidate, one direction, the default probe batch of noises, forward only, cached views."""
    start = time.perf_counter()
    pose = torch.tensor([[0.2, 1.0, 0.0]]).expand(PROBE_BATCH, 3)
    noise = torch.randn(PROBE_BATCH, *views.noise_shape, generator=generator)
    index = torch.zeros(PROBE_BATCH, dtype=torch.long)
    with torch.no_grad():
        predictor.noise_error(views, index, index + 1, pose, torch.full((PROBE_BATCH,), probe_step(predictor)), noise)
    return {"total": time.perf_counter() - start}


def official_probe(predictor, images, generator) -> dict:
    """One official probe: the probe batch of repeated reference and target images re-encoded, UNet forward."""
    start = time.perf_counter()
    refs, tgts = images[:1].expand(PROBE_BATCH, -1, -1, -1), images[1:].expand(PROBE_BATCH, -1, -1, -1)
    ref_latents, tgt_latents, embeds = official_encode(predictor, refs, tgts, generator)
    encoded = time.perf_counter()
    with torch.no_grad():
        t = torch.full((PROBE_BATCH,), probe_step(predictor))
        noise = torch.randn(tgt_latents.shape, generator=generator)
        noisy = predictor.modules.scheduler.add_noise(tgt_latents, noise, t)
        pose = torch.tensor([[0.2, 1.0, 0.0]]).expand(PROBE_BATCH, 3)
        eps = predictor.predict_noise(noisy, ref_latents, t, predictor.pose_tokens(embeds, pose))
        (eps - noise).square().mean(dim=(1, 2, 3))
    end = time.perf_counter()
    return {"total": end - start, "encode": encoded - start, "unet_forward": end - encoded}


def reset_peak_rss() -> None:
    """Restart the kernel's peak-RSS count (VmHWM), so the run's peak is seen apart from building the model."""
    Path("/proc/self/clear_refs").write_text("5")


def peak_rss_since_reset_gb() -> float:
    """Peak resident memory since ``reset_peak_rss`` (Linux /proc VmHWM), in GiB."""
    line = next(line for line in Path("/proc/self/status").read_text().splitlines() if line.startswith("VmHWM:"))
    return int(line.split()[1]) / 1024**2


def current_rss_gb() -> float:
    """Resident memory now (Linux /proc), in GiB."""
    pages = int(Path("/proc/self/statm").read_text().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 1024**3


def summarise(runs: dict, args: argparse.Namespace, load_before: tuple) -> dict:
    """Medians per kind, the official/ours ratios per precision, and the machine the figures come from."""
    units = ("seconds", "cpu_seconds", "peak_gb", "run_peak_gb")
    median = {kind: {unit: statistics.median(r[unit] for r in results) for unit in units}
              for kind, results in runs.items()}
    for kind, results in runs.items():
        if kind.startswith("ours_adjust"):
            median[kind]["per_sample_seconds"] = statistics.median(r["parts"]["per_sample"] for r in results)
    ratios = {
        precision: {f"{what}_{unit}": median[f"official_{what}"][unit] / median[f"ours_{what}@{precision}"][unit]
                    for what in ("step", "probe") for unit in units}
        for precision in args.precisions
    }
    return {
        "machine": {"cpus": os.cpu_count(), "threads": args.threads, "platform": platform.platform(),
                    "torch": torch.__version__, "load_average_before": load_before,
                    "load_average_after": os.getloadavg()},
        "setup": {"config": args.config, "image_size": args.size, "official_dtype": "float32",
                  "precisions": args.precisions, "weights": "random", "alternations": args.alternations,
                  "repeats_per_step_measurement": args.repeats, "probe_batch": PROBE_BATCH,
                  "adjusted_candidates": ADJUSTED_CANDIDATES, "grad_batch": DEFAULTS.grad_batch,
                  "definitions": __doc__.split("What is measured")[1].split("Usage:")[0]},
        "runs": runs,
        "median": median,
        "ratio_official_over_ours": ratios,
    }


def print_summary(report: dict) -> None:
    median = report["median"]
    print(f"\n{'kind':<24}{'seconds':>10}{'CPU s':>10}{'peak GB':>10}{'run GB':>10}")
    for kind, figures in median.items():
        extra = f"  ({figures['per_sample_seconds']:.2f} s per sample)" if "per_sample_seconds" in figures else ""
        print(f"{kind:<24}{figures['seconds']:>10.2f}{figures['cpu_seconds']:>10.2f}{figures['peak_gb']:>10.2f}"
              f"{figures['run_peak_gb']:>10.2f}{extra}")
    official_parts = report["runs"]["official_step"][0]["parts"]
    print("official step split (first run): " + ", ".join(f"{k} {v:.2f} s" for k, v in official_parts.items()))
    for precision, ratio in report["ratio_official_over_ours"].items():
        for what in ("step", "probe"):
            print(f"{what} vs ours in {precision}: official / ours = {ratio[what + '_seconds']:.2f}x time "
                  f"({ratio[what + '_cpu_seconds']:.2f}x CPU time), {ratio[what + '_peak_gb']:.2f}x peak memory "
                  f"({ratio[what + '_run_peak_gb']:.2f}x while running)")
    load = report["machine"]
    print(f"load average before {load['load_average_before']}, after {load['load_average_after']} "
          f"({load['cpus']} CPUs, {load['threads']} threads)")


if __name__ == "__main__":
    main()
