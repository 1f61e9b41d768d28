"""The view intake on a lifecycle node of its own, without the estimator: an image and the inputs of its stamp
become one view, a bad image is refused with its reason, and images go into the buffer only while active."""
from __future__ import annotations

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import LifecycleNode
from rclpy.qos import qos_profile_sensor_data
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import Image
from std_msgs.msg import Header

from idpose_ros.node.flight_recorder import FlightRecorder
from idpose_ros.node.input_sync import InputSync
from idpose_ros.node.lifecycle import Lifecycle
from idpose_ros.node.node_state import NodeState
from idpose_ros.node.parameters import parameter_table
from idpose_ros.node.raw_image import RawImage
from idpose_ros.node.view_buffer import CaptureRefused, ImageRefused, ViewBuffer
from idpose_ros.node.view_intake import ViewIntake
from msg_adapters import array_to_image, matrix_to_pose

pytestmark = pytest.mark.slow  # a node per test (no process, no spinning executor thread)
DEFAULTS = {name: default for name, default, _ in parameter_table()}


class Intake:
    """A ViewIntake on a fresh lifecycle node, with the settings and activity a test sets."""

    def __init__(self, context, name: str, gravity: str = "auto", **settings) -> None:
        self.node = LifecycleNode(name, context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.state = NodeState({**DEFAULTS, "capture_mode": "on_request", **settings}, Lifecycle.ACTIVE)
        self.kept: list[int] = []
        self.buffer = ViewBuffer(self.state.settings.max_views)
        recorder = FlightRecorder("", 0, self.buffer.snapshot, print, print)
        self.intake = ViewIntake(self.node, self.state, self.buffer, InputSync(gravity), recorder, self.kept.append)

    def publish_and_spin(self, message: Image, until) -> None:
        """Publish ``message`` on the node's own image topic and spin until ``until()``."""
        publisher = self.node.create_publisher(Image, "image", qos_profile_sensor_data)
        for _ in range(200):
            publisher.publish(message)
            self.executor.spin_once(timeout_sec=0.05)
            if until():
                return
        raise AssertionError("the image never arrived")

    def witness(self) -> list[Image]:
        """A second subscription to the image topic, made after the intake's (the executor serves those first): what
        reached the node, whatever the intake did with it."""
        seen: list[Image] = []
        self.node.create_subscription(Image, "image", seen.append, qos_profile_sensor_data)
        return seen


@pytest.fixture
def intake(ros_context, request):
    made: list[Intake] = []

    def make(**settings) -> Intake:
        made.append(Intake(ros_context, f"intake_{request.node.name}_{len(made)}", **settings))
        return made[-1]

    yield make
    for each in made:
        each.executor.shutdown()
        each.node.destroy_node()


def rgba(object_views, sec: int) -> Image:
    rgb, alpha = object_views[0]
    return array_to_image(np.dstack([rgb, alpha]), "rgba8", Header(frame_id="cam", stamp=Time(sec=sec)))


def test_a_view_takes_the_camera_pose_of_its_stamp_as_gravity_and_arm_pose(intake, object_views):
    made = intake()
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_euler("xyz", [-100.0, 0.0, 20.0], degrees=True).as_matrix()
    pose[:3, 3] = [0.3, 0.1, 0.5]
    now = made.node.get_clock().now().nanoseconds
    made.intake.sync.add_orientation(PoseStamped(header=Header(stamp=Time(sec=5)), pose=matrix_to_pose(pose)), now)
    view = made.intake.prepare(RawImage(rgba(object_views, 5), "image"))
    np.testing.assert_allclose(view.input.camera_pose, pose, atol=1e-9)
    np.testing.assert_allclose(view.input.gravity_up, pose[:3, :3].T @ [0.0, 0.0, 1.0], atol=1e-9)
    assert view.source == "Image rgba8" and view.input.alpha is not None and not view.pending


def test_bad_images_are_refused_with_their_reason(intake, object_views):
    required = intake(gravity="required")
    with pytest.raises(ImageRefused, match=r"no gravity reading .*gravity: required"):
        required.intake.prepare(RawImage(rgba(object_views, 5), "image"))
    small = intake(max_image_pixels=32 * 32)
    with pytest.raises(ImageRefused, match=r"max_image_pixels"):
        small.intake.prepare(RawImage(rgba(object_views, 5), "image"))
    blank = array_to_image(np.zeros((64, 64, 4), np.uint8), "rgba8", Header(stamp=Time(sec=5)))
    with pytest.raises(ImageRefused, match="Image rgba8 on image"):
        small.intake.prepare(RawImage(blank, "image"))
    assert len(required.buffer) == len(small.buffer) == 0


def test_capture_keeps_the_latest_image_once(intake, object_views):
    made = intake()
    made.intake.subscribe()
    with pytest.raises(CaptureRefused):
        made.intake.capture()
    made.publish_and_spin(rgba(object_views, 5), lambda: made.intake.images_received)
    view, count = made.intake.capture()
    assert count == 1 and made.kept == [1] and view.stamp.sec == 5
    with pytest.raises(CaptureRefused):
        made.intake.capture()
    assert len(made.buffer) == 1, "the same image is not kept twice"


def test_auto_capture_keeps_images_only_while_active(intake, object_views):
    made = intake(capture_mode="auto", min_view_interval=0.0)
    made.intake.subscribe()
    made.state.lifecycle = Lifecycle.INACTIVE
    seen = made.witness()
    made.publish_and_spin(rgba(object_views, 5), lambda: len(seen) >= 3)
    assert made.intake.images_received == 0 and len(made.buffer) == 0, "inactive: images ignored"
    made.state.lifecycle = Lifecycle.ACTIVE
    made.publish_and_spin(rgba(object_views, 6), lambda: made.kept)
    assert made.kept[0] == 1 and made.intake.images_received >= 1
