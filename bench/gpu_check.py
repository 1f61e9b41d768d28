#!/usr/bin/env python3
"""A GPU check in minutes: full-size Zero-1-to-3 step and probe cost per precision, and one estimate per preset.

Random weights (the cost does not depend on the values), 256 px. Per precision (float16, bfloat16,
float32; ``load_predictor``'s rule: the UNet in that dtype, the rest float32): seconds of one solver
refinement step (one sample, forward + backward to the pose) and one probe (16 samples, forward only),
and the peak memory of each (CUDA: ``max_memory_allocated``; CPU: peak resident memory since the model
was built). The official way's step (``bench/step_cost.py``: re-encoding, weight gradients, gradient
checkpointing; float32 as its code runs) gives the per-step ratio official / ours. The step is also timed
under the node's cancellation hooks (``checked_in_modules``: a Python check in every module call, forward
and backward), which may cost a large share of a short GPU step. Then one two-view estimate per preset on
the same random model in the first precision: its predictor samples and seconds (``live`` with the second
view's elevation given, as gravity gives it).

``--reduced`` runs the tiny architecture at 64 px with shortened schedules, so it finishes on a CPU
in seconds (a smoke test of this script; its figures mean nothing). Prints a table, writes JSON.

    python bench/gpu_check.py [--device cuda] [--precisions float16 bfloat16 float32] [--reduced]
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

import torch  # noqa: E402 (after the path setup)

from bench.result_files import result_path  # noqa: E402
from bench.step_cost import (  # noqa: E402
    official_step,
    ours_probe,
    ours_step,
    peak_rss_since_reset_gb,
    prepare_official,
    reset_peak_rss,  # noqa: E402
)
from idpose_core.cancellation import checked_in_modules  # noqa: E402
from idpose_core.devices import DeviceUnavailable, resolve_device  # noqa: E402
from idpose_core.model_loading import PRECISIONS  # noqa: E402
from idpose_core.solver import SolverConfig, estimate_poses  # noqa: E402
from idpose_core.solver.config import PRESETS  # noqa: E402
from idpose_core.zero123 import Zero123Config, Zero123Predictor  # noqa: E402

OUT = result_path("gpu_check")
# --reduced: schedules cut to a few samples per stage where the preset leaves the setting at its default
REDUCED_SCHEDULE = dict(azimuth_candidates=2, polar_candidates_deg=(0.0,), adjust_steps=1, refine_steps_per_view=2,
                        runner_up_steps=1, start_steps=2, average_last=1, probe_batch=2)
GRAVITY_POLAR_DEG = -20.0  # the relative elevation handed to a preset made for gravity


def synchronized(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def reset_peak(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.reset_peak_memory_stats(device)
    else:
        reset_peak_rss()


def peak_gb(device: torch.device) -> float:
    """Peak memory since ``reset_peak``: CUDA allocations, or this process's resident memory on the CPU."""
    return torch.cuda.max_memory_allocated(device) / 1024**3 if device.type == "cuda" else peak_rss_since_reset_gb()


def timed(device: torch.device, work, repeats: int) -> dict[str, float]:
    """Mean seconds of ``repeats`` calls after one warm-up, and the peak memory over them."""
    work()
    synchronized(device)
    reset_peak(device)
    seconds = []
    for _ in range(repeats):
        start = time.perf_counter()
        work()
        synchronized(device)
        seconds.append(time.perf_counter() - start)
    return {"seconds": statistics.mean(seconds), "peak_gb": peak_gb(device)}


def random_model(args: argparse.Namespace, precision: str) -> Zero123Predictor:
    config = Zero123Config.tiny() if args.reduced else Zero123Config.full()
    return Zero123Predictor.random(config, seed=0, device=args.device, dtype=PRECISIONS[precision])


def unit_costs(args: argparse.Namespace, images: torch.Tensor, precision: str) -> dict[str, dict[str, float]]:
    """Step and probe seconds and peak memory of our path in ``precision``."""
    predictor = random_model(args, precision)
    views = predictor.encode(images)
    generator = torch.Generator().manual_seed(0)
    device = torch.device(args.device)

    def hooked_step() -> None:
        with checked_in_modules(threading.Event(), lambda: "a timed step"):
            ours_step(predictor, views, generator)

    return {"step": timed(device, lambda: ours_step(predictor, views, generator), args.repeats),
            "step_with_cancel_hooks": timed(device, hooked_step, args.repeats),
            "probe": timed(device, lambda: ours_probe(predictor, views, generator), args.repeats)}


def official(args: argparse.Namespace, images: torch.Tensor) -> dict[str, float]:
    """The official way's step, float32."""
    predictor = random_model(args, "float32")
    prepare_official(predictor)
    generator = torch.Generator().manual_seed(0)
    return timed(torch.device(args.device), lambda: official_step(predictor, images, generator), args.repeats)


def estimates(args: argparse.Namespace, images: torch.Tensor, precision: str) -> dict[str, dict]:
    """One two-view estimate per preset: predictor samples and seconds; a preset made for gravity (``live``) is
    given the second view's relative polar angle (``GRAVITY_POLAR_DEG``), as gravity would."""
    predictor = random_model(args, precision)
    out = {}
    for preset in args.presets:
        shorter = {name: value for name, value in REDUCED_SCHEDULE.items() if name not in PRESETS[preset]}
        config = SolverConfig.preset(preset, **(shorter if args.reduced else {}))
        start = time.perf_counter()
        known_polar = [math.radians(GRAVITY_POLAR_DEG)] if config.gravity_fallback else None
        result = estimate_poses(predictor, images, config, known_polar=known_polar)
        synchronized(torch.device(args.device))
        out[preset] = {"forward_samples": result.forward_samples, "backward_samples": result.backward_samples,
                       "seconds": time.perf_counter() - start, "elevation_known": known_polar is not None}
        print(f"estimate {preset} ({precision}): {out[preset]}", flush=True)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    parser.add_argument("--precisions", nargs="+", choices=("float16", "bfloat16", "float32"),
                        default=["float16", "bfloat16", "float32"])
    parser.add_argument("--presets", nargs="+", choices=tuple(PRESETS), default=list(PRESETS))
    parser.add_argument("--repeats", type=int, default=3, help="timed calls per measurement (after a warm-up)")
    parser.add_argument("--reduced", action="store_true", help="tiny architecture, 64 px, short schedules")
    parser.add_argument("--threads", type=int, default=2, help="torch threads on the CPU")
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    try:
        resolve_device(args.device)
    except DeviceUnavailable as err:
        parser.exit(2, f"gpu_check: {err}\n")
    torch.set_num_threads(args.threads)
    started = time.monotonic()
    size = 64 if args.reduced else 256
    images = (torch.rand(2, 3, size, size, generator=torch.Generator().manual_seed(0)) * 2 - 1).to(args.device)
    report = {"device": args.device, "device_name": torch.cuda.get_device_name(args.device)
              if args.device.startswith("cuda") else "cpu", "torch": torch.__version__, "reduced": args.reduced,
              "precisions": {}}
    for precision in args.precisions:
        report["precisions"][precision] = unit_costs(args, images, precision)
        print(f"{precision}: {report['precisions'][precision]}", flush=True)
    report["official_step_float32"] = official(args, images)
    report["step_ratio_official_over_ours"] = {
        precision: report["official_step_float32"]["seconds"] / costs["step"]["seconds"]
        for precision, costs in report["precisions"].items()}
    report["estimate_precision"] = args.precisions[0]
    report["estimates"] = estimates(args, images, args.precisions[0])
    report["minutes"] = (time.monotonic() - started) / 60
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"\n{report['device_name']}, torch {report['torch']}{' (reduced)' if args.reduced else ''}")
    print("| precision | step s | step peak GB | step with cancel hooks s | probe (16) s | probe peak GB "
          "| official step / ours |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for precision, costs in report["precisions"].items():
        hooked = costs["step_with_cancel_hooks"]["seconds"]
        print(f"| {precision} | {costs['step']['seconds']:.3f} | {costs['step']['peak_gb']:.2f} | {hooked:.3f} "
              f"(+{100 * (hooked / costs['step']['seconds'] - 1):.0f} %) | {costs['probe']['seconds']:.3f} | "
              f"{costs['probe']['peak_gb']:.2f} | {report['step_ratio_official_over_ours'][precision]:.2f}x |")
    print(f"official step (float32): {report['official_step_float32']['seconds']:.3f} s, "
          f"{report['official_step_float32']['peak_gb']:.2f} GB")
    for preset, row in report["estimates"].items():
        gravity = ", elevation known" if row["elevation_known"] else ""
        print(f"estimate {preset} ({report['estimate_precision']}{gravity}): {row['forward_samples']} samples "
              f"({row['backward_samples']} differentiated), {row['seconds']:.1f} s")
    print(f"{report['minutes']:.1f} min; wrote {args.out}")


if __name__ == "__main__":
    main()
