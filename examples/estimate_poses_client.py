"""Capture views with the estimator node, estimate their poses through the EstimatePoses action, print them.

Start the node with on-request capture (``-p capture_mode:=on_request``), then
``python examples/estimate_poses_client.py views/``: it publishes the PNG files of ``views/`` in name
order (the first is the anchor; an alpha channel is the object mask) and keeps each with ``~/capture``,
sends one goal on the buffered views, prints the feedback as it comes and reads the typed result.
"""
import sys
from pathlib import Path

import cv2
import rclpy
from rclpy.action import ActionClient
from rclpy.node import Node
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import Image
from std_srvs.srv import Trigger

from idpose_interfaces.action import EstimatePoses
from msg_adapters import array_to_image


def capture(node: Node, images, client, path: Path) -> str:
    """Publish the PNG at ``path`` until ``~/capture`` has kept it; the node's answer."""
    bgra = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    message = array_to_image(bgra, "bgra8" if bgra.shape[2] == 4 else "bgr8")
    message.header.frame_id, message.header.stamp = "camera_optical", node.get_clock().now().to_msg()
    while True:
        images.publish(message)
        rclpy.spin_once(node, timeout_sec=0.1)
        future = client.call_async(Trigger.Request())
        rclpy.spin_until_future_complete(node, future)
        if future.result().success:
            return future.result().message


def main() -> int:
    rclpy.init(args=sys.argv)
    folder = Path(remove_ros_args(sys.argv)[1])
    node = Node("estimate_poses_client")
    images = node.create_publisher(Image, "image", 10)
    capture_client = node.create_client(Trigger, "idpose_estimator/capture")
    action = ActionClient(node, EstimatePoses, "idpose_estimator/estimate_poses")
    capture_client.wait_for_service()
    action.wait_for_server()
    while images.get_subscription_count() == 0:  # until the estimator subscribes
        rclpy.spin_once(node, timeout_sec=0.1)
    for path in sorted(folder.glob("*.png")):
        print(path.name, "->", capture(node, images, capture_client, path))

    def on_feedback(message) -> None:
        feedback = message.feedback
        print(f"feedback: {feedback.stage} {feedback.progress:.0%}, {feedback.forward_samples} samples, "
              f"{feedback.seconds_elapsed:.1f} s")

    sent = action.send_goal_async(EstimatePoses.Goal(), feedback_callback=on_feedback)  # no images: the buffer
    rclpy.spin_until_future_complete(node, sent)
    finished = sent.result().get_result_async()
    rclpy.spin_until_future_complete(node, finished)
    result = finished.result().result
    if result.error_code != EstimatePoses.Result.SUCCEEDED:
        print(f"run {result.run_id} failed (error code {result.error_code}): {result.error_message}")
        return 1
    print(f"run {result.run_id}: {len(result.views)} poses in frame '{result.poses.header.frame_id}' "
          f"after {result.seconds:.1f} s")
    for k, view in enumerate(result.views):
        p, q = view.pose.position, view.pose.orientation
        print(f"view {k}: position ({p.x:.3f}, {p.y:.3f}, {p.z:.3f}) m, quaternion ({q.x:.3f}, {q.y:.3f}, "
              f"{q.z:.3f}, {q.w:.3f}), confidence {view.confidence:.2f}" + (", ambiguous" if view.ambiguous else ""))
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
