"""The estimator node's resident memory through its lifecycle: does cleanup give the model's memory back?

The node runs in this process (autostart off) on a Zero-1-to-3 folder with random weights in the
``--config`` architecture (full: the released model's, about 1.2 B parameters), saved once to a
temporary folder. Its lifecycle is walked by hand, twice: configure (the model loads), activate and
one EstimatePoses goal on two rendered views with a minimal solver (the weights are memory-mapped
until used: the estimate makes them resident, as in service), deactivate, cleanup (the model is
freed). The process's RSS (Linux VmRSS) is read after each step; the second cycle shows whether
memory grows from one configuration to the next.

Usage (from the repository root): python -m bench.lifecycle_memory [--config full|tiny]
Writes bench/results/lifecycle_memory/lifecycle_memory.json and prints one line per step.
"""
from __future__ import annotations

import argparse
import json
import platform
import tempfile
import threading
from pathlib import Path

import numpy as np
import rclpy
from rclpy.action import ActionClient
from rclpy.executors import MultiThreadedExecutor
from rclpy.parameter import Parameter
from sensor_msgs.msg import Image

from bench.result_files import result_path
from idpose_core.synthetic.scenes import SceneRenderer, demo_objects
from idpose_core.zero123 import Zero123Config, Zero123Predictor
from idpose_interfaces.action import EstimatePoses
from idpose_ros.node.estimator_node import EstimatorNode
from msg_adapters import array_to_image

OUT = result_path("lifecycle_memory")
STEPS = ("configure", "activate", "estimate", "deactivate", "cleanup")
MINIMAL_SOLVER = dict(azimuth_candidates=1, probe_batch=1, adjust_steps=0, keep_top=1, refine_steps_per_view=1,
                      average_last=1, runner_up_steps=0)


def rss_gb() -> float:
    """This process's resident set size in GB (VmRSS)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024**2
    raise RuntimeError("no VmRSS in /proc/self/status (Linux only)")


def two_views() -> list[Image]:
    """Two 256 px renders of a demo object, with their alpha masks."""
    with SceneRenderer(demo_objects()[0], image_size=256) as renderer:
        renders = [renderer.render(np.radians(80.0), np.radians(azimuth), 2.0) for azimuth in (0.0, 60.0)]
    return [array_to_image(np.dstack([rgb, (mask * 255).astype(np.uint8)]), "rgba8") for rgb, mask in renders]


def estimate(client: ActionClient, images: list[Image]) -> str:
    """Send one goal and wait for its end; the result's error code name."""
    handle = wait(client.send_goal_async(EstimatePoses.Goal(images=images)))
    result = wait(handle.get_result_async()).result
    return {getattr(EstimatePoses.Result, name): name for name in ("SUCCEEDED", "INVALID_GOAL", "MODEL_UNAVAILABLE",
                                                                   "FAILED", "CANCELED", "BUSY", "NOT_ACTIVE")
            }[result.error_code]


def wait(future):
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    done.wait()
    return future.result()


def walk(node: EstimatorNode, client: ActionClient, images: list[Image], cycle: int) -> list[dict]:
    """One configure .. cleanup cycle with an estimate while active; the RSS after each step."""
    rows = []
    for step in STEPS:
        outcome = estimate(client, images) if step == "estimate" else getattr(node, f"trigger_{step}")().name
        rows.append({"cycle": cycle, "step": step, "state": node.lifecycle_state, "model": node.status().model,
                     "rss_gb": round(rss_gb(), 3), "outcome": outcome})
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
            overrides = {"model_path": folder, "device": "cpu", "autostart": False, "publish_tf": False,
                         "image_size": 256 if args.config == "full" else 32, **MINIMAL_SOLVER}
            node = EstimatorNode(parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()])
            client_node = rclpy.create_node("lifecycle_memory_client")
            client = ActionClient(client_node, EstimatePoses, "idpose_estimator/estimate_poses")
            executor = MultiThreadedExecutor(num_threads=4)
            for each in (node, client_node):
                executor.add_node(each)
            threading.Thread(target=executor.spin, daemon=True).start()
            client.wait_for_server()
            images = two_views()
            rows = walk(node, client, images, 1) + walk(node, client, images, 2)
            executor.shutdown(timeout_sec=1.0)
            node.destroy_node()
        finally:
            rclpy.try_shutdown()
    active = max(row["rss_gb"] for row in rows if row["step"] == "estimate")
    cleaned = [row["rss_gb"] for row in rows if row["step"] == "cleanup"]
    summary = {"config": args.config, "rss_before_node_gb": round(before, 3), "rss_active_gb": active,
               "rss_after_cleanup_gb": cleaned, "freed_share": round((active - cleaned[-1]) / (active - before), 3),
               "machine": platform.processor() or platform.machine(), "steps": rows}
    freed = 100 * summary["freed_share"]
    print(f"active after an estimate {active:.3f} GB, after cleanup {cleaned[-1]:.3f} GB: {freed:.0f} % of the "
          "model's memory given back", flush=True)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(summary, indent=1) + "\n")


if __name__ == "__main__":
    main()
