"""The estimated camera poses on TF: ``<anchor frame> -> <tf_prefix>view_<k>`` for every view of an estimate, and
``<anchor frame> -> <tf_prefix>next_view`` for the camera it suggests next.

tf2_ros's broadcaster where it is installed (a ROS workspace); else a ``tf2_msgs/TFMessage`` lifecycle publisher
on ``/tf`` with the same QoS (what that broadcaster is), where tf2_msgs alone is installed; else nothing, said
once in the log. PyPI has no tf2_ros or tf2_msgs wheel. Either way nothing goes on TF while the node is not active.
"""
from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

from geometry_msgs.msg import PoseArray, PoseStamped, TransformStamped
from rclpy.lifecycle import LifecycleNode, SimpleManagedEntity
from rclpy.qos import DurabilityPolicy, QoSProfile

from msg_adapters import pose_array_to_transforms

TF_TOPIC = "/tf"
TF_QOS = QoSProfile(depth=100, durability=DurabilityPolicy.VOLATILE)  # tf2_ros.TransformBroadcaster's default


def view_frame(prefix: str, index: int) -> str:
    """The child frame of view ``index`` (0 = the anchor)."""
    return f"{prefix}view_{index}"


def next_view_frame(prefix: str) -> str:
    """The child frame of the suggested next camera."""
    return f"{prefix}next_view"


class _WhileActive(SimpleManagedEntity):
    """tf2_ros's broadcaster publishes through a plain publisher of its own: its sends pass only while the node is
    active, as a lifecycle publisher's do."""

    def __init__(self, send: Callable[[list[TransformStamped]], None]) -> None:
        super().__init__()
        self._send = send

    @SimpleManagedEntity.when_enabled
    def __call__(self, transforms: list[TransformStamped]) -> None:
        self._send(transforms)


def _sender(node: LifecycleNode) -> tuple[Callable[[list[TransformStamped]], None] | None, str]:
    """A function that puts transforms on /tf while the node is active, and what it uses; (None, why) when neither
    package imports."""
    try:
        broadcaster = importlib.import_module("tf2_ros").TransformBroadcaster(node)
    except ImportError:
        pass
    else:
        send = _WhileActive(broadcaster.sendTransform)
        node.add_managed_entity(send)
        return send, "tf2_ros"
    try:
        message = importlib.import_module("tf2_msgs.msg").TFMessage
    except ImportError:
        return None, "neither tf2_ros nor tf2_msgs is installed"
    publisher = node.create_lifecycle_publisher(message, TF_TOPIC, TF_QOS)
    return lambda transforms: publisher.publish(message(transforms=transforms)), "tf2_msgs"


class PoseBroadcaster:
    """Broadcasts each estimate's poses on TF; off (with one log line saying why) without tf2."""

    def __init__(self, node: LifecycleNode, log: Callable[[str], Any]) -> None:
        self._send, self.backend = _sender(node)
        if self._send is None:
            log(f"publish_tf is on but TF is off: {self.backend} (source a ROS 2 installation that has tf2_ros)")

    @property
    def enabled(self) -> bool:
        return self._send is not None

    def broadcast(self, poses: PoseArray, prefix: str, next_view: PoseStamped) -> None:
        """``poses.header.frame_id -> prefix + view_<k>`` and ``-> prefix + next_view`` (``next_view`` is in the same
        frame), stamped with the poses' (the anchor's) stamp."""
        if self._send is not None:
            frames = [view_frame(prefix, k) for k in range(len(poses.poses))] + [next_view_frame(prefix)]
            every = PoseArray(header=poses.header, poses=[*poses.poses, next_view.pose])
            self._send(pose_array_to_transforms(every, frames))
