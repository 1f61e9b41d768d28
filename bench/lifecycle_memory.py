"""The estimator node's resident memory through its lifecycle: does cleanup give the model's memory back?

The node runs in this process (autostart off) on a Zero-1-to-3 folder with random weights in the
``--config`` architecture (full: the released model's, about 1.2 B parameters), saved once to a
temporary folder. Its lifecycle is walked by hand, twice: configure (the model loads), activate,
deactivate, cleanup (the model is freed). The process's RSS (Linux VmRSS) is read after each step;
a second configure/cleanup cycle shows whether memory grows from one configuration to the next.

Usage (from the repository root): python -m bench.lifecycle_memory [--config full|tiny]
Writes bench/results/lifecycle_memory.json and prints one line per step.
"""
from __future__ import annotations

import argparse
import json
import platform
import tempfile
from pathlib import Path

import rclpy
from rclpy.parameter import Parameter

from idpose_core.zero123 import Zero123Config, Zero123Predictor
from idpose_ros.node.estimator_node import EstimatorNode

RESULTS = Path(__file__).resolve().parent / "results"
STEPS = ("configure", "activate", "deactivate", "cleanup")


def rss_gb() -> float:
    """This process's resident set size in GB (VmRSS)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024**2
    raise RuntimeError("no VmRSS in /proc/self/status (Linux only)")


def walk(node: EstimatorNode, cycle: int) -> list[dict]:
    """One configure .. cleanup cycle; the RSS after each transition."""
    rows = []
    for step in STEPS:
        outcome = getattr(node, f"trigger_{step}")()
        rows.append({"cycle": cycle, "step": step, "state": node.lifecycle_state, "model": node.status().model,
                     "rss_gb": round(rss_gb(), 3), "outcome": outcome.name})
        print(f"cycle {cycle}: {step:<10} -> {node.lifecycle_state:<12} model {rows[-1]['model']:<10} "
              f"RSS {rows[-1]['rss_gb']:.3f} GB", flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", choices=("full", "tiny"), default="full")
    args = parser.parse_args()
    config = Zero123Config.full() if args.config == "full" else Zero123Config.tiny()
    with tempfile.TemporaryDirectory(prefix="idpose_lifecycle_") as folder:
        Zero123Predictor.random(config, seed=0).save_pretrained(folder)  # freed before the node starts
        rclpy.init()
        try:
            before = rss_gb()
            print(f"before the node: RSS {before:.3f} GB", flush=True)
            node = EstimatorNode(parameter_overrides=[Parameter("model_path", value=folder),
                                                      Parameter("device", value="cpu"),
                                                      Parameter("autostart", value=False),
                                                      Parameter("publish_tf", value=False)])
            rows = walk(node, 1) + walk(node, 2)
            node.destroy_node()
        finally:
            rclpy.try_shutdown()
    active = max(row["rss_gb"] for row in rows if row["step"] == "activate")
    cleaned = [row["rss_gb"] for row in rows if row["step"] == "cleanup"]
    summary = {"config": args.config, "rss_before_node_gb": round(before, 3), "rss_active_gb": active,
               "rss_after_cleanup_gb": cleaned, "freed_share": round((active - cleaned[-1]) / (active - before), 3),
               "machine": platform.processor() or platform.machine(), "steps": rows}
    print(f"active {active:.3f} GB, after cleanup {cleaned[-1]:.3f} GB: {100 * summary['freed_share']:.0f} % of the "
          "model's memory given back", flush=True)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "lifecycle_memory.json").write_text(json.dumps(summary, indent=1) + "\n")


if __name__ == "__main__":
    main()
