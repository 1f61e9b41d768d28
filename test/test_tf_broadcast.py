"""PoseBroadcaster on a real lifecycle node: without tf2 it is off and says why once; with tf2_msgs (the test
stand-in) every view and the next camera go on /tf, named by the prefix and stamped with the anchor's stamp, and only
while the node is active."""
from __future__ import annotations

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import LifecycleNode

from idpose_ros.node.tf_broadcast import TF_QOS, TF_TOPIC, PoseBroadcaster, next_view_frame, view_frame
from msg_adapters import matrix_to_pose, poses_to_pose_array

pytestmark = pytest.mark.slow  # starts nodes

STAMP = Time(sec=7, nanosec=5)


def estimate() -> tuple:
    """Two views' poses in the anchor's frame "cam" and a suggested next camera."""
    second = np.eye(4)
    second[:3, 3] = (0.1, 0.0, 0.02)
    poses = poses_to_pose_array(np.stack([np.eye(4), second]), "cam", STAMP)
    return poses, PoseStamped(header=poses.header, pose=matrix_to_pose(second))


def test_without_tf2_the_broadcaster_is_off_and_says_why_once(ros_context):
    node = LifecycleNode("tf_off", context=ros_context)
    said: list[str] = []
    try:
        broadcaster = PoseBroadcaster(node, said.append)
        assert not broadcaster.enabled and broadcaster.backend == "neither tf2_ros nor tf2_msgs is installed"
        poses, next_camera = estimate()
        broadcaster.broadcast(poses, "robot/", next_camera)  # nothing to send with: no error either
        assert len(said) == 1 and "publish_tf is on but TF is off" in said[0]
    finally:
        node.destroy_node()


def test_each_view_and_the_next_camera_go_on_tf_only_while_active(ros_context, tf2_msgs, wait_for):
    from tf2_msgs.msg import TFMessage

    node = LifecycleNode("tf_on", context=ros_context)
    probe = LifecycleNode("tf_probe", context=ros_context)
    received: list = []
    probe.create_subscription(TFMessage, TF_TOPIC, received.append, TF_QOS)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(probe)
    try:
        broadcaster = PoseBroadcaster(node, lambda line: None)
        assert broadcaster.enabled and broadcaster.backend == "tf2_msgs"
        node.trigger_configure()
        wait_for(lambda: probe.count_publishers(TF_TOPIC) > 0, "the /tf publisher")
        poses, next_camera = estimate()
        broadcaster.broadcast(poses, "robot/", next_camera)  # configured, not active: nothing
        executor.spin_once(timeout_sec=0.5)
        assert not received
        node.trigger_activate()
        broadcaster.broadcast(poses, "robot/", next_camera)
        wait_for(lambda: executor.spin_once(timeout_sec=0.1) or received, "the transforms")
        (message,) = received
        assert [t.child_frame_id for t in message.transforms] == [view_frame("robot/", 0), view_frame("robot/", 1),
                                                                   next_view_frame("robot/")]
        assert all(t.header.frame_id == "cam" and t.header.stamp == STAMP for t in message.transforms)
        assert abs(message.transforms[1].transform.translation.x - 0.1) < 1e-9
    finally:
        executor.shutdown()
        probe.destroy_node()
        node.destroy_node()
