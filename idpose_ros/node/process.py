"""`ros2 run idpose_ros estimator`: the estimator node's process, from start to a clean exit on Ctrl-C."""
from __future__ import annotations

import logging
import os
import signal
import sys
from typing import Any

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from idpose_ros.node.estimator_node import EstimatorNode

SPIN_PERIOD = 0.1  # s: the main thread sees Ctrl-C at least this often
EXECUTOR_THREADS = 4  # images, inputs, services and goals each keep a thread while the solver runs on its own


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt(signal.Signals(signum).name)


def run(args: list[str] | None = None) -> int:
    """Run the node until Ctrl-C (SIGINT/SIGTERM) or a ROS shutdown; returns the exit code (2: invalid parameters).

    rclpy's own signal handler would invalidate the context at once; here the signal raises
    KeyboardInterrupt in the spin loop instead, so the node still logs while it cancels and stops.
    """
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    for signum in (signal.SIGINT, signal.SIGTERM):  # also when started with SIGINT ignored (`node &` in a script)
        signal.signal(signum, _interrupt)
    try:
        node = EstimatorNode()  # with autostart, the model loads here
    except ParameterException:  # logged by the node, under its full name
        rclpy.try_shutdown()
        return 2
    except KeyboardInterrupt:  # while the model loaded
        rclpy.try_shutdown()
        return 0
    executor = MultiThreadedExecutor(num_threads=EXECUTOR_THREADS)
    executor.add_node(node)
    try:
        while rclpy.ok():
            executor.spin_once(timeout_sec=SPIN_PERIOD)
    except (KeyboardInterrupt, ExternalShutdownException):
        node.get_logger().info("interrupted: shutting down")
    finally:
        if not node.stop():
            node.get_logger().warning("the estimate did not stop in time; exiting anyway (it is a daemon thread)")
        executor.shutdown(timeout_sec=0.2)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def main() -> None:
    """Entry point of `ros2 run idpose_ros estimator`.

    Exits with ``os._exit`` once ROS is shut down and the output flushed: the interpreter's own
    teardown of torch, diffusers and transformers takes seconds, and Ctrl-C must end the node
    within 2 s even in the middle of an estimate.
    """
    code = run()
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":
    main()
