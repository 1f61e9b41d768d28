"""Placeholder for the estimator node until it is built: says so and exits non-zero."""
import sys

import rclpy


def main() -> int:
    rclpy.init()
    node = rclpy.create_node("idpose_estimator")
    node.get_logger().error("the idpose_ros estimator is not implemented yet; nothing was estimated")
    node.destroy_node()
    rclpy.shutdown()
    return 1


if __name__ == "__main__":
    sys.exit(main())
