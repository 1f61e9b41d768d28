"""Run every benchmark in order and rewrite the tables of bench/README.md from their results.

Usage (from anywhere, after ``./run test`` has built the venv): .venv/bin/python bench/run_all.py
       [--reuse-step-cost]   keep an existing bench/results/step_cost/step_cost.json (that one needs ~12 GB and minutes)
Each benchmark runs in its own process from the repository root; the first failure stops the run.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

from bench.result_files import result_path  # noqa: E402

STEP_COST_JSON = result_path("step_cost")
BENCHMARKS = (
    ("1. step and probe cost, ours vs official (full-size model)", ["bench/step_cost.py"]),
    ("1b. bfloat16 vs float32 on the same samples (full-size model)", ["bench/precision_fidelity.py"]),
    ("2. samples per estimate and projected time", ["-m", "bench.sample_counts"]),
    ("3. accuracy vs schedule on the render oracle", ["-m", "bench.oracle_schedule"]),
    ("4. end to end with the demo model", ["-m", "bench.end_to_end"]),
    ("tables -> bench/README.md", ["-m", "bench.report"]),
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reuse-step-cost", action="store_true", help="skip item 1 when its result file exists")
    args = parser.parse_args()
    for title, command in BENCHMARKS:
        if command[0] == "bench/step_cost.py" and args.reuse_step_cost and STEP_COST_JSON.is_file():
            print(f"== {title}: reusing {STEP_COST_JSON}", flush=True)
            continue
        print(f"== {title}", flush=True)
        start = time.perf_counter()
        subprocess.run([sys.executable, *command], cwd=ROOT, check=True)
        print(f"== done in {time.perf_counter() - start:.0f} s", flush=True)


if __name__ == "__main__":
    main()
