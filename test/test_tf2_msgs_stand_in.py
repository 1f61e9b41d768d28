"""The stand-in tf2_msgs (conftest's ``tf2_msgs`` fixture) carries TFMessages between real rclpy nodes, in
this process and from a subprocess, and is gone once the test that asked for it ends."""
import importlib.util
import subprocess
import sys
import textwrap

import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

pytestmark = pytest.mark.slow  # every test here starts a node or a process, or takes seconds

FRAMES = {"view_1": (0.5, -0.25, 1.0), "view_2": (-1.5, 0.0, 2.0)}
# Publishes the FRAMES on /tf ten times a second until stopped (or 60 s), as a node under test would.
PUBLISHER = textwrap.dedent(f"""
    import time
    import rclpy
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage

    rclpy.init()
    node = rclpy.create_node("tf_stand_in_publisher")
    publisher = node.create_publisher(TFMessage, "/tf", 10)
    transforms = []
    for child, (x, y, z) in {FRAMES!r}.items():
        transform = TransformStamped()
        transform.header.frame_id, transform.child_frame_id = "anchor", child
        transform.transform.translation.x, transform.transform.translation.y = x, y
        transform.transform.translation.z = z
        transforms.append(transform)
    for _ in range(600):
        publisher.publish(TFMessage(transforms=transforms))
        time.sleep(0.1)
""")


def tf_message():
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage

    transforms = []
    for child, (x, y, z) in FRAMES.items():
        transform = TransformStamped()
        transform.header.frame_id, transform.child_frame_id = "anchor", child
        transform.header.stamp.sec = 42
        transform.transform.translation.x, transform.transform.translation.y = x, y
        transform.transform.translation.z = z
        transforms.append(transform)
    return TFMessage(transforms=transforms)


def frames_of(message) -> dict[str, tuple[float, float, float]]:
    return {t.child_frame_id: (t.transform.translation.x, t.transform.translation.y, t.transform.translation.z)
            for t in message.transforms if t.header.frame_id == "anchor"}


def subscribe(context, received: list):
    """A node subscribed to /tf, appending what arrives to ``received``, and an executor spinning it."""
    from tf2_msgs.msg import TFMessage

    node = Node("tf_stand_in_subscriber", context=context)
    node.create_subscription(TFMessage, "/tf", received.append, 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    return node, executor


def test_a_publisher_and_a_subscriber_in_this_process_exchange_a_tf_message(tf2_msgs, ros_context, wait_for):
    from tf2_msgs.msg import TFMessage

    assert importlib.util.find_spec("tf2_msgs").origin.startswith(str(tf2_msgs))
    received: list = []
    subscriber, executor = subscribe(ros_context, received)
    publisher_node = Node("tf_stand_in_publisher", context=ros_context)
    executor.add_node(publisher_node)
    publisher = publisher_node.create_publisher(TFMessage, "/tf", 10)
    try:
        def delivered():
            publisher.publish(tf_message())
            executor.spin_once(timeout_sec=0.1)
            return received

        wait_for(delivered, "a TFMessage on /tf", timeout=30)
    finally:
        executor.shutdown()
        publisher_node.destroy_node()
        subscriber.destroy_node()
    assert isinstance(received[0], TFMessage)
    assert frames_of(received[0]) == FRAMES
    assert {t.header.stamp.sec for t in received[0].transforms} == {42}


def test_a_subprocess_started_by_the_test_publishes_tf_messages(tf2_msgs, ros_context, wait_for):
    received: list = []
    subscriber, executor = subscribe(ros_context, received)
    process = subprocess.Popen([sys.executable, "-c", PUBLISHER], stderr=subprocess.PIPE, text=True)
    try:
        def delivered():
            assert process.poll() is None, f"the publisher exited: {process.stderr.read()}"
            executor.spin_once(timeout_sec=0.1)
            return received

        wait_for(delivered, "a TFMessage from the subprocess", timeout=60)
    finally:
        process.kill()
        process.wait()
        executor.shutdown()
        subscriber.destroy_node()
    assert frames_of(received[0]) == FRAMES


def test_the_stand_in_is_gone_after_the_tests_that_used_it(tf2_msgs_prefix):
    assert not any(name.split(".")[0] == "tf2_msgs" for name in sys.modules)
    spec = importlib.util.find_spec("tf2_msgs")  # a real tf2_msgs may exist in a ROS workspace; not the stand-in
    assert spec is None or not spec.origin.startswith(str(tf2_msgs_prefix))
