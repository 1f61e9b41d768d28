"""A bag's views and their ground-truth camera poses, as numpy: images, /tf + /tf_static, PoseStamped.

Images and PoseStamped are deserialized by rclpy into real message classes (so decoding stays in
``msg_adapters``); /tf and /tf_static go through ``rosbags`` (tf2_msgs is not available to rclpy
here) into ``idpose_core.transforms.TransformBuffer``. Glue only: no maths of its own.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from geometry_msgs.msg import PoseStamped
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from tqdm import tqdm

from idpose_core.evaluation import match_stamps
from idpose_core.transforms import TransformBuffer, TransformLookupError
from idpose_ros.bag_io import BagError, open_bag, topic_connections
from msg_adapters import AdapterError, camera_info_to_matrix, compressed_to_rgb, image_to_rgb, pose_to_matrix

IMAGE_TYPES = {"sensor_msgs/msg/Image": Image, "sensor_msgs/msg/CompressedImage": CompressedImage}
CAMERA_INFO_TYPE = "sensor_msgs/msg/CameraInfo"
TRANSPORTS = ("compressed", "compressedDepth", "theora", "zstd")  # image_transport's sub-topic suffixes
TF_TYPE = "tf2_msgs/msg/TFMessage"
POSE_TYPE = "geometry_msgs/msg/PoseStamped"


def stamp_ns(stamp) -> int:
    """builtin_interfaces Time (rclpy or rosbags) -> integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


@dataclass(frozen=True)
class ViewInfo:
    """One image of the image topic: its position on the topic, header stamp (ns) and frame."""

    view_id: int
    stamp: int
    frame_id: str


@dataclass(frozen=True)
class BagViews:
    """Every image on the topic (``views``), the ground truth of the usable ones and why others are skipped.

    ``world_from_camera[view_id]`` (4, 4) is the camera's optical frame in the world frame;
    ``skipped[view_id]`` says why a view has no usable ground truth or image; ``camera_matrix`` (3, 3) is K
    of the first CameraInfo on ``camera_info_topic``, or None when the bag has no calibrated one there.
    """

    views: list[ViewInfo]
    world_from_camera: dict[int, np.ndarray]
    skipped: dict[int, str]
    camera_info_topic: str = ""
    camera_matrix: np.ndarray | None = None

    @property
    def pool(self) -> list[int]:
        """The usable view ids, in capture order."""
        return sorted(self.world_from_camera)


def default_camera_info_topic(image_topic: str) -> str:
    """The camera_info topic beside an image topic, as image_transport names it: /cam/image_raw[/compressed]
    -> /cam/camera_info."""
    base = image_topic.rstrip("/")
    if base.rsplit("/", 1)[-1] in TRANSPORTS:
        base = base.rsplit("/", 1)[0]
    return f"{base.rsplit('/', 1)[0]}/camera_info"


def _camera_matrix(reader, topic: str) -> np.ndarray | None:
    """K of the first CameraInfo on ``topic``; None when the topic is absent or the camera uncalibrated."""
    connections = [c for c in reader.connections if c.topic == topic and c.msgtype == CAMERA_INFO_TYPE]
    for _, _, raw in (reader.messages(connections=connections) if connections else ()):
        try:
            return camera_info_to_matrix(deserialize_message(raw, CameraInfo))
        except AdapterError:
            return None
    return None


def decode_view(message: Image | CompressedImage) -> tuple[np.ndarray, np.ndarray | None]:
    """(rgb (H, W, 3) uint8, alpha (H, W) uint8 | None) of an Image or CompressedImage, via msg_adapters."""
    return (image_to_rgb if isinstance(message, Image) else compressed_to_rgb)(message)


def _scan_images(reader, image_topic: str) -> tuple[list[ViewInfo], dict[int, str]]:
    """Header of every image on the topic (in bag order) and the ids of those that do not decode."""
    views, broken = [], {}
    connections = topic_connections(reader, image_topic, tuple(IMAGE_TYPES))
    scan = tqdm(reader.messages(connections=connections), total=sum(c.msgcount for c in connections),
                desc=f"reading {image_topic}", unit="image", file=sys.stderr, leave=False)
    for view_id, (connection, _, raw) in enumerate(scan):
        message = deserialize_message(raw, IMAGE_TYPES[connection.msgtype])
        try:
            decode_view(message)
        except AdapterError as err:
            broken[view_id] = f"bad image: {err}"
        views.append(ViewInfo(view_id, stamp_ns(message.header.stamp), message.header.frame_id.lstrip("/")))
    return views, broken


def _transform_buffer(reader) -> TransformBuffer:
    """Every transform on /tf and /tf_static of the bag (stamped by their headers)."""
    buffer = TransformBuffer()
    for topic, static in (("/tf", False), ("/tf_static", True)):
        connections = [c for c in reader.connections if c.topic == topic and c.msgtype == TF_TYPE]
        for _, _, raw in (reader.messages(connections=connections) if connections else ()):
            for item in reader.deserialize(raw, TF_TYPE).transforms:
                t, q = item.transform.translation, item.transform.rotation
                try:
                    buffer.add(item.header.frame_id, item.child_frame_id, stamp_ns(item.header.stamp),
                               np.array([t.x, t.y, t.z]), np.array([q.x, q.y, q.z, q.w]), static=static)
                except ValueError as err:
                    raise BagError(f"{topic}: {err}") from None
    return buffer


def _ground_truth_from_tf(reader, views: list[ViewInfo], world_frame: str
                          ) -> tuple[dict[int, np.ndarray], dict[int, str]]:
    buffer = _transform_buffer(reader)
    if not buffer.frames:
        raise BagError("the bag has no transforms on /tf or /tf_static; give the ground truth with --gt-topic")
    poses, skipped = {}, {}
    for view in views:
        try:
            poses[view.view_id] = buffer.lookup(world_frame, view.frame_id, view.stamp)
        except TransformLookupError as err:
            skipped[view.view_id] = f"no ground truth: {err}"
    return poses, skipped


def _ground_truth_from_topic(reader, views: list[ViewInfo], topic: str, world_frame: str, tolerance: int
                             ) -> tuple[dict[int, np.ndarray], dict[int, str]]:
    stamps, matrices = [], []
    for _, _, raw in reader.messages(connections=topic_connections(reader, topic, (POSE_TYPE,))):
        message = deserialize_message(raw, PoseStamped)
        if message.header.frame_id.lstrip("/") != world_frame:
            raise BagError(f"{topic} gives poses in frame {message.header.frame_id!r}, not in the world frame "
                           f"{world_frame!r} (set --world-frame)")
        try:
            matrices.append(pose_to_matrix(message.pose))
        except AdapterError as err:
            raise BagError(f"{topic}: {err}") from None
        stamps.append(stamp_ns(message.header.stamp))
    matches = match_stamps([view.stamp for view in views], stamps, tolerance)
    poses = {view.view_id: matrices[index] for view, index in zip(views, matches) if index >= 0}
    skipped = {view.view_id: f"no ground truth: no {topic} pose within {tolerance * 1e-9:g} s of the image stamp "
                             f"{view.stamp * 1e-9:.9f} s" for view, index in zip(views, matches) if index < 0}
    return poses, skipped


def read_bag_views(path: str | Path, image_topic: str, world_frame: str = "world", gt_topic: str | None = None,
                   gt_tolerance: float = 0.01, camera_info_topic: str | None = None) -> BagViews:
    """The views of ``image_topic`` and their ground truth from /tf (default) or the PoseStamped ``gt_topic``.

    A view without ground truth (or whose image does not decode) is kept in ``skipped`` with the
    reason. ``gt_tolerance`` (s) bounds the stamp difference when matching ``gt_topic`` poses. The
    intrinsics come from ``camera_info_topic`` (default: the image topic's camera_info).
    """
    world_frame = world_frame.lstrip("/")
    camera_info_topic = camera_info_topic or default_camera_info_topic(image_topic)
    with open_bag(path) as reader:
        camera_matrix = _camera_matrix(reader, camera_info_topic)
        views, broken = _scan_images(reader, image_topic)
        if gt_topic is None:
            poses, skipped = _ground_truth_from_tf(reader, views, world_frame)
        else:
            poses, skipped = _ground_truth_from_topic(reader, views, gt_topic, world_frame,
                                                      int(round(gt_tolerance * 1e9)))
    for view_id, reason in broken.items():
        poses.pop(view_id, None)
        skipped[view_id] = reason
    return BagViews(views=views, world_from_camera=poses, skipped=dict(sorted(skipped.items())),
                    camera_info_topic=camera_info_topic, camera_matrix=camera_matrix)


def load_view_messages(path: str | Path, image_topic: str, view_ids: set[int]
                       ) -> dict[int, Image | CompressedImage]:
    """The image messages of the chosen views, read again from the bag (decode with ``decode_view``)."""
    messages = {}
    with open_bag(path) as reader:
        connections = topic_connections(reader, image_topic, tuple(IMAGE_TYPES))
        for view_id, (connection, _, raw) in enumerate(reader.messages(connections=connections)):
            if view_id in view_ids:
                messages[view_id] = deserialize_message(raw, IMAGE_TYPES[connection.msgtype])
    return messages
