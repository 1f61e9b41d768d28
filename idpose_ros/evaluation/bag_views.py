"""A bag's views and their ground-truth camera poses, as numpy: images, /tf + /tf_static, PoseStamped.

Images and PoseStamped are deserialized by rclpy into real message classes (so decoding stays in
``msg_adapters``); /tf and /tf_static go through ``rosbags`` (tf2_msgs need not be installed for
rclpy) into ``idpose_core.transforms.TransformBuffer``. Scanning checks each image's layout without
decoding it; ``load_views`` decodes the views an evaluation uses, once. Glue only: no maths of its own.
"""
from __future__ import annotations

import sys
from collections.abc import Iterator
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

import numpy as np
from geometry_msgs.msg import PoseStamped, QuaternionStamped
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, Imu
from tqdm import tqdm

from idpose_core.gravity import (
    IMU_WINDOW_S,
    GravityUnavailable,
    resting_acceleration,
    rotation_from_extrinsic,
    up_from_acceleration,
    up_from_orientation,
)
from idpose_core.stamps import INPUT_TOLERANCE_S, match_stamps
from idpose_core.transforms import TransformBuffer, TransformLookupError
from idpose_core.view_input import ViewInput
from idpose_ros.evaluation.bag_io import BagError, open_bag, topic_connections
from idpose_ros.view_decoding import MessageView, ViewMessages, decode_view
from msg_adapters import (
    AdapterError,
    check_image,
    imu_acceleration,
    orientation_rotation,
    pose_to_matrix,
    stamp_nanoseconds,
)

IMAGE_TYPES = {"sensor_msgs/msg/Image": Image, "sensor_msgs/msg/CompressedImage": CompressedImage}
TRANSPORTS = ("compressed", "compressedDepth", "theora", "zstd")  # image_transport's sub-topic suffixes
TF_TYPE = "tf2_msgs/msg/TFMessage"
POSE_TYPE = "geometry_msgs/msg/PoseStamped"
EXTRA_TYPES = {"depth": {"sensor_msgs/msg/Image": Image}, "mask": {"sensor_msgs/msg/Image": Image},
               "camera_info": {"sensor_msgs/msg/CameraInfo": CameraInfo}}
IMU_TYPE = "sensor_msgs/msg/Imu"
GRAVITY_TYPES = {IMU_TYPE: Imu, POSE_TYPE: PoseStamped, "geometry_msgs/msg/QuaternionStamped": QuaternionStamped}


@dataclass(frozen=True)
class ViewInfo:
    """One image of the image topic: its position on the topic, header stamp (ns) and frame."""

    view_id: int
    stamp: int
    frame_id: str


@dataclass(frozen=True)
class ExtraTopics:
    """A view's inputs besides its image, each matched to the image by stamp within ``tolerance`` s (the
    CameraInfo nearest in time, when the bag has the topic at all).

    ``gravity_topic`` carries sensor_msgs/Imu (its acceleration averaged over the ``imu_window`` s
    before the image, turned into the optical frame by ``imu_to_optical`` (a quaternion x y z w or roll
    pitch yaw in radians, as the node's parameter takes it) or else by the bag's transforms from the
    Imu's frame to the image's) or the camera's orientation in a frame whose
    +z is up (geometry_msgs/PoseStamped or QuaternionStamped); a PoseStamped also gives the camera's pose in
    that frame, as the node's ``camera_pose`` topic does (the arm's pose hypotheses). A view that lacks a
    requested input is skipped, with the reason.
    """

    depth_topic: str | None = None
    mask_topic: str | None = None
    camera_info_topic: str | None = None
    gravity_topic: str | None = None
    imu_to_optical: tuple[float, ...] | None = None
    tolerance: float = INPUT_TOLERANCE_S
    imu_window: float = IMU_WINDOW_S

    @property
    def topics(self) -> dict[str, str]:
        """Requested image-like inputs: kind -> topic."""
        return {kind: topic for kind, topic in (("depth", self.depth_topic), ("mask", self.mask_topic),
                                                ("camera_info", self.camera_info_topic)) if topic}


@dataclass(frozen=True)
class ViewSources:
    """Where one view's other inputs are: per kind (depth, mask, camera_info) the index of the matched message
    on its topic, world up in the view's optical frame when a gravity topic was given, and the camera's optical
    frame in the fixed frame (4, 4) when that topic is a PoseStamped (the arm's camera pose)."""

    messages: dict[str, int] = field(default_factory=dict)
    gravity_up: np.ndarray | None = None
    camera_pose: np.ndarray | None = None


@dataclass(frozen=True)
class BagViews:
    """Every image on the topic (``views``), the ground truth of the usable ones and why others are skipped.

    ``world_from_camera[view_id]`` (4, 4) is the camera's optical frame in the world frame;
    ``skipped[view_id]`` says why a view has no usable ground truth, image or requested input;
    ``extras[view_id]`` where the view's other inputs are (``ExtraTopics``).
    """

    views: list[ViewInfo]
    world_from_camera: dict[int, np.ndarray]
    skipped: dict[int, str]
    extras: dict[int, ViewSources] = field(default_factory=dict)  # usable view id -> its matched inputs

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


def _scan_images(reader, image_topic: str) -> tuple[list[ViewInfo], dict[int, str]]:
    """Header of every image on the topic (in bag order) and the ids of those that are not well formed (checked
    without decoding their pixels)."""
    views, broken = [], {}
    connections = topic_connections(reader, image_topic, tuple(IMAGE_TYPES))
    scan = tqdm(reader.messages(connections=connections), total=sum(c.msgcount for c in connections),
                desc=f"reading {image_topic}", unit="image", file=sys.stderr, leave=False)
    for view_id, (connection, _, raw) in enumerate(scan):
        message = deserialize_message(raw, IMAGE_TYPES[connection.msgtype])
        try:
            check_image(message)
        except AdapterError as err:
            broken[view_id] = f"bad image: {err}"
        views.append(ViewInfo(view_id, stamp_nanoseconds(message.header.stamp), message.header.frame_id.lstrip("/")))
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
                    buffer.add(item.header.frame_id, item.child_frame_id, stamp_nanoseconds(item.header.stamp),
                               np.array([t.x, t.y, t.z]), np.array([q.x, q.y, q.z, q.w]), static=static)
                except ValueError as err:
                    raise BagError(f"{topic}: {err}") from None
    return buffer


def _ground_truth_from_tf(buffer: TransformBuffer, views: list[ViewInfo], world_frame: str
                          ) -> tuple[dict[int, np.ndarray], dict[int, str]]:
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
        stamps.append(stamp_nanoseconds(message.header.stamp))
    matches = match_stamps([view.stamp for view in views], stamps, tolerance)
    poses = {view.view_id: matrices[index] for view, index in zip(views, matches) if index >= 0}
    skipped = {view.view_id: f"no ground truth: no {topic} pose within {tolerance * 1e-9:g} s of the image stamp "
                             f"{view.stamp * 1e-9:.9f} s" for view, index in zip(views, matches) if index < 0}
    return poses, skipped


def _read(reader, topic: str, types: dict[str, type]) -> Iterator[tuple[int, object]]:
    """(header stamp, message) of every message on ``topic``, which must carry one of ``types``, one at a time."""
    for connection, _, raw in reader.messages(connections=topic_connections(reader, topic, tuple(types))):
        message = deserialize_message(raw, types[connection.msgtype])
        yield stamp_nanoseconds(message.header.stamp), message


def _gravity(reader, views: list[ViewInfo], extras: ExtraTopics, buffer: TransformBuffer
             ) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray], dict[int, str]]:
    """World up in each view's optical frame from ``extras.gravity_topic``, the camera's pose where that topic is
    a PoseStamped, or why a view has none."""
    readings = list(_read(reader, extras.gravity_topic, GRAVITY_TYPES))
    tolerance, window = int(round(extras.tolerance * 1e9)), int(round(extras.imu_window * 1e9))
    ups, poses, missing = {}, {}, {}
    if readings and isinstance(readings[0][1], Imu):
        stamps = np.array([stamp for stamp, _ in readings])
        try:
            accelerations = np.stack([imu_acceleration(message) for _, message in readings])
        except AdapterError as err:
            raise BagError(f"{extras.gravity_topic}: {err}") from None
        imu_frame = readings[0][1].header.frame_id.lstrip("/")
        for view in views:
            try:
                a = resting_acceleration(stamps, accelerations, view.stamp, window, tolerance)
                if extras.imu_to_optical is not None:
                    optical_from_imu = rotation_from_extrinsic(extras.imu_to_optical)
                else:
                    optical_from_imu = buffer.lookup(view.frame_id, imu_frame, view.stamp)[:3, :3]
                ups[view.view_id] = up_from_acceleration(a, optical_from_imu)
            except (GravityUnavailable, TransformLookupError) as err:
                missing[view.view_id] = f"no gravity: {err}"
        return ups, poses, missing
    matches = match_stamps([view.stamp for view in views], [stamp for stamp, _ in readings], tolerance)
    for view, index in zip(views, matches):
        if index < 0:
            missing[view.view_id] = (f"no gravity: no {extras.gravity_topic} orientation within "
                                     f"{extras.tolerance:g} s of the image stamp")
            continue
        try:
            ups[view.view_id] = up_from_orientation(orientation_rotation(readings[index][1]))
        except AdapterError as err:
            missing[view.view_id] = f"no gravity: {err}"
            continue
        if isinstance(readings[index][1], PoseStamped):
            poses[view.view_id] = pose_to_matrix(readings[index][1].pose)
    return ups, poses, missing


def _sources(reader, views: list[ViewInfo], extras: ExtraTopics, buffer: TransformBuffer
             ) -> tuple[dict[int, ViewSources], dict[int, str]]:
    """Each view's matched inputs (``ExtraTopics``), or why one is missing."""
    tolerance = int(round(extras.tolerance * 1e9))
    matched: dict[int, dict[str, int]] = {view.view_id: {} for view in views}
    missing: dict[int, str] = {}
    for kind, topic in extras.topics.items():
        if kind == "camera_info" and topic not in reader.topics:
            continue  # intrinsics are optional: without them depth is not used and baselines assume a field of view
        stamps = [stamp for stamp, _ in _read(reader, topic, EXTRA_TYPES[kind])]
        limit = np.iinfo(np.int64).max if kind == "camera_info" else tolerance  # intrinsics rarely change
        for view, index in zip(views, match_stamps([view.stamp for view in views], stamps, limit)):
            if index < 0:
                missing.setdefault(view.view_id, f"no {kind}: nothing on {topic} within {extras.tolerance:g} s of "
                                                 f"the image stamp {view.stamp * 1e-9:.3f} s")
            matched[view.view_id][kind] = int(index)
    ups, poses = {}, {}
    if extras.gravity_topic:
        ups, poses, no_gravity = _gravity(reader, views, extras, buffer)
        for view_id, reason in no_gravity.items():
            missing.setdefault(view_id, reason)
    return {view_id: ViewSources(kinds, ups.get(view_id), poses.get(view_id)) for view_id, kinds in matched.items()
            if view_id not in missing}, missing


def read_bag_views(path: str | Path, image_topic: str, world_frame: str = "world", gt_topic: str | None = None,
                   gt_tolerance: float = 0.01, extras: ExtraTopics = ExtraTopics()) -> BagViews:
    """The views of ``image_topic``, their ground truth from /tf (default) or the PoseStamped ``gt_topic``, and
    where their other inputs are (``extras``).

    A view without ground truth, whose image does not decode, or that lacks a requested input is kept
    in ``skipped`` with the reason. ``gt_tolerance`` (s) bounds the stamp difference when matching
    ``gt_topic`` poses.
    """
    world_frame = world_frame.lstrip("/")
    with open_bag(path) as reader:
        views, broken = _scan_images(reader, image_topic)
        needs_tf = gt_topic is None or (extras.gravity_topic and extras.imu_to_optical is None)
        buffer = _transform_buffer(reader) if needs_tf else TransformBuffer()
        if gt_topic is None:
            poses, skipped = _ground_truth_from_tf(buffer, views, world_frame)
        else:
            poses, skipped = _ground_truth_from_topic(reader, views, gt_topic, world_frame,
                                                      int(round(gt_tolerance * 1e9)))
        sources, missing = _sources(reader, views, extras, buffer)
    for view_id, reason in {**missing, **broken}.items():
        poses.pop(view_id, None)
        skipped[view_id] = reason
    return BagViews(views=views, world_from_camera=poses, skipped=dict(sorted(skipped.items())),
                    extras={view_id: sources[view_id] for view_id in poses})


def _read_view_messages(path: str | Path, image_topic: str, view_ids: set[int], bag: BagViews,
                        extras: ExtraTopics) -> dict[int, ViewMessages]:
    """The chosen views' messages, read again from the bag (their other inputs as ``bag.extras`` matched them)."""
    messages: dict[int, ViewMessages] = {}
    wanted: dict[str, dict[int, list[int]]] = {}  # kind -> message index on its topic -> views
    for view_id in view_ids:
        for kind, index in bag.extras[view_id].messages.items():
            wanted.setdefault(kind, {}).setdefault(index, []).append(view_id)
    with open_bag(path) as reader:
        connections = topic_connections(reader, image_topic, tuple(IMAGE_TYPES))
        for view_id, (connection, _, raw) in enumerate(reader.messages(connections=connections)):
            if view_id in view_ids:
                messages[view_id] = ViewMessages(deserialize_message(raw, IMAGE_TYPES[connection.msgtype]),
                                                 gravity_up=bag.extras[view_id].gravity_up,
                                                 camera_pose=bag.extras[view_id].camera_pose)
        for kind, topic in extras.topics.items():
            if kind not in wanted:
                continue
            types = EXTRA_TYPES[kind]
            for index, (connection, _, raw) in enumerate(
                    reader.messages(connections=topic_connections(reader, topic, tuple(types)))):
                for view_id in wanted[kind].get(index, ()):
                    messages[view_id] = replace(messages[view_id],
                                                **{kind: deserialize_message(raw, types[connection.msgtype])})
    return messages


def load_views(path: str | Path, image_topic: str, view_ids: set[int], bag: BagViews,
               extras: ExtraTopics = ExtraTopics()) -> tuple[dict[int, ViewInput], dict[int, str]]:
    """The chosen usable views decoded, once each, with their other inputs (as ``bag.extras`` matched them) and the
    messages they came from (``MessageView``); and why any of them could not be decoded (view id -> reason), so that
    only the estimates holding it fail."""
    views, problems = {}, {}
    for view_id, view in _read_view_messages(path, image_topic, view_ids, bag, extras).items():
        try:
            decoded = decode_view(view.image, view.depth, view.mask, view.camera_info, view.gravity_up,
                                  camera_pose=view.camera_pose)
            views[view_id] = MessageView(**{f.name: getattr(decoded, f.name) for f in fields(ViewInput)},
                                         messages=view)
        except AdapterError as err:
            problems[view_id] = f"it does not decode: {err}"
    return views, problems
