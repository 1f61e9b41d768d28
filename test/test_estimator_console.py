"""`ros2 run idpose_ros estimator` as a user runs it: the colcon-installed console script, in a subprocess.

The node comes up from install/ (after sourcing install/setup.sh), refuses ~/estimate without
views, starts an estimate on two views, and a Ctrl-C (SIGINT) in the middle of it ends the
process cleanly within 2 s. Reduced: the tiny random Zero-1-to-3 on 32 px views, 2 azimuth
candidates, probe batch 1, no adjustment steps; refinement made endless (10^6 steps) so that
the SIGINT lands during the run; torch on one thread (test/conftest.py).
"""
import os
import signal
import subprocess
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import Image
from std_msgs.msg import Header
from std_srvs.srv import Trigger

from idpose_ros.diagnostics import STATUS_NAME
from msg_adapters import array_to_image

NAMESPACE = "/console"
NODE = f"{NAMESPACE}/idpose_estimator"
SHUTDOWN_LIMIT = 2.0  # seconds, the requirement for Ctrl-C during an estimate


def test_the_installed_estimator_refuses_without_views_and_stops_on_ctrl_c_mid_estimate(
        workspace, tiny_model_dir, ros_context, object_views, wait_for, tmp_path):
    executable = workspace / "install" / "idpose_ros" / "lib" / "idpose_ros" / "estimator"
    arguments = " ".join(f"-p {name}:={value}" for name, value in {
        "model_path": tiny_model_dir, "image_size": 32, "min_view_interval": 0.0, "diagnostics_period": 0.1,
        "azimuth_candidates": 2, "probe_batch": 1, "adjust_steps": 0, "keep_top": 1,
        "refine_steps_per_view": 1_000_000}.items())
    command = f". {workspace / 'install' / 'setup.sh'} && exec {executable} --ros-args -r __ns:={NAMESPACE} {arguments}"
    log = tmp_path / "estimator.log"
    with log.open("w") as output:
        process = subprocess.Popen(["bash", "-c", command], stdout=output, stderr=subprocess.STDOUT,
                                   env=os.environ)
    probe = Node("console_probe", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(probe)
    status: dict[str, str] = {}

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for entry in msg.status:
            if entry.name == STATUS_NAME and entry.hardware_id.startswith(f"{NODE} ("):
                status.clear()
                status.update({kv.key: kv.value for kv in entry.values})

    def spin_until(predicate, what: str, timeout: float = 60.0):
        def step():
            executor.spin_once(timeout_sec=0.05)
            assert process.poll() is None, f"the estimator exited early:\n{log.read_text()}"
            return predicate()
        return wait_for(step, what, timeout)

    def call(name: str) -> Trigger.Response:
        client = probe.create_client(Trigger, f"{NODE}/{name}")
        spin_until(lambda: client.service_is_ready(), f"{NODE}/{name}")
        future = client.call_async(Trigger.Request())
        return spin_until(future.result, f"the answer of {NODE}/{name}")

    try:
        probe.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
        images = probe.create_publisher(Image, f"{NAMESPACE}/image", 10)
        refusal = call("estimate")
        assert not refusal.success and refusal.message == "need at least 2 buffered views to estimate, have 0"

        spin_until(lambda: images.get_subscription_count() > 0, "the node's image subscription")
        for index, (rgb, alpha) in enumerate(object_views[:2]):
            images.publish(array_to_image(np.dstack([rgb, alpha]), "rgba8", Header(frame_id=f"cam{index}")))
            spin_until(lambda: status.get("views_buffered") == str(index + 1), f"view {index + 1} to be buffered")
        assert call("estimate").success
        spin_until(lambda: status.get("stage") == "refinement", "the estimate to reach refinement")

        process.send_signal(signal.SIGINT)
        interrupted = time.monotonic()
        try:
            code = process.wait(timeout=SHUTDOWN_LIMIT)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"no exit within {SHUTDOWN_LIMIT} s of SIGINT:\n{log.read_text()}") from None
        print(f"estimator exited {time.monotonic() - interrupted:.2f} s after SIGINT")
        assert code == 0, log.read_text()
        assert "shutting down: cancelling the running estimate" in log.read_text()
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        executor.shutdown()
        probe.destroy_node()
