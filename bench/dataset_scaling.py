#!/usr/bin/env python3
"""evaluate_dataset on a local Ray instance with the embedded demo model: 1 vs 2 workers, and the merged report.

1. Wall time of the same 24 estimates (the six shipped demo bags x 4 picks, n = 2; `fast` preset) with
   ``--workers 1`` and ``--workers 2``, one CPU (= one torch thread) per worker, each run a fresh command
   (Ray start-up and model loading included), and their ratio.
2. The report: the six bags (the first pick, n = 2 and 4) and the official omni3d samples
   (``../shared/reference/idpose-official/omni3d.json``: three objects, 4 views each, n = 2 and 4) run
   into the two-worker run's folder, which already holds the bags' n = 2 estimates of that pick (a
   rerun skips them). The demo model knows only its six synthetic objects: omni3d is at chance.

Prints the figures, writes bench/results/dataset_scaling/dataset_scaling.json and the merged report as
bench/results/dataset_scaling/dataset_report.md.

    python bench/dataset_scaling.py [--samples 4] [--preset fast]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

from bench.result_files import result_path  # noqa: E402

OUT, REPORT = result_path("dataset_scaling"), result_path("dataset_scaling", "dataset_report.md")
OMNI3D = ROOT.parent / "shared" / "reference" / "idpose-official" / "omni3d.json"


def evaluate_dataset(arguments: list[str]) -> float:
    """Run the command in a fresh process (its own local Ray instance); its wall seconds."""
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "idpose_ros.evaluate_dataset", *arguments], cwd=ROOT, check=False)
    return time.perf_counter() - start


def estimates_of(out: Path) -> dict:
    """Counts and per-estimate seconds of a run's results.jsonl."""
    lines = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    return {"estimates": len(lines), "succeeded": sum(line["status"] == "ok" for line in lines),
            "estimate_seconds": sum(line.get("seconds", 0.0) for line in lines),
            "per_worker": dict(Counter(line.get("worker", "none") for line in lines))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=4, help="picks per bag (4: 24 estimates of n = 2)")
    parser.add_argument("--preset", choices=("default", "fast"), default="fast")
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    bags = [str(path) for path in sorted((ROOT / "data" / "demo_bags").iterdir()) if (path / "metadata.yaml").is_file()]
    common = ["--seed", "0", "--preset", args.preset, "--num-cpus-per-worker", "1"]
    result = {"arguments": vars(args) | {"out": os.path.relpath(args.out, ROOT)}, "cpus": os.cpu_count(), "runs": {}}
    with tempfile.TemporaryDirectory(prefix="idpose_dataset_scaling_") as folder:
        for workers in (1, 2):
            out = Path(folder) / f"workers_{workers}"
            load = os.getloadavg()
            seconds = evaluate_dataset([*bags, *common, "--samples", str(args.samples), "--n", "2",
                                        "--workers", str(workers), "--out", str(out)])
            result["runs"][str(workers)] = {"workers": workers, "wall_seconds": seconds,
                                            "load_average_before": load, **estimates_of(out)}
            print(f"== {workers} worker(s): {seconds:.0f} s wall", flush=True)
        one, two = result["runs"]["1"], result["runs"]["2"]
        result["speedup"] = one["wall_seconds"] / two["wall_seconds"]
        if OMNI3D.is_file():
            out = Path(folder) / "workers_2"
            seconds = evaluate_dataset([*bags, str(OMNI3D), *common, "--samples", "1", "--n", "2", "4",
                                        "--workers", "2", "--out", str(out)])
            report = json.loads((out / "report.json").read_text())
            result["report"] = {"wall_seconds_of_the_rerun": seconds, "estimates": report["estimates"],
                                "datasets": report["datasets"], "all": report["all"]}
            shutil.copy(out / "report.md", REPORT)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"\n{one['estimates']} estimates: 1 worker {one['wall_seconds']:.0f} s, "
          f"2 workers {two['wall_seconds']:.0f} s wall, "
          f"speed-up {result['speedup']:.2f}x (estimate seconds summed: {one['estimate_seconds']:.0f} / "
          f"{two['estimate_seconds']:.0f})")
    for dataset, scores in result.get("report", {}).get("datasets", {}).items():
        model, random = scores["aggregates"]["all"], scores["random_baseline"]["aggregates"]["all"]
        print(f"{dataset}: {model['pairs']} pairs, RotAcc@15 {100 * model['rot_acc_15']:.1f} %, RotAcc@30 "
              f"{100 * model['rot_acc_30']:.1f} %, mean {model['mean_rot_err_deg']:.1f} deg; random poses "
              f"{100 * random['rot_acc_15']:.1f} / {100 * random['rot_acc_30']:.1f} %")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
