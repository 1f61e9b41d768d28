"""Synthetic bags: pybullet views of an object from random cameras, written into a real rosbag2.

Topics: ``/camera/image_raw`` (sensor_msgs/Image: ``rgba8`` with alpha = object mask on white for
``--scene plain``, ``rgb8`` for ``--scene tabletop``), ``/camera/camera_info``, ``/camera/pose``
(geometry_msgs/PoseStamped, the optical frame in ``world``: ground truth for ``--gt-topic``), ``/tf``
(world -> base_link -> camera_link, the robot moving between views) and ``/tf_static`` (camera_link ->
camera_optical_frame and camera_link -> camera_imu_frame), ``/camera/imu`` (sensor_msgs/Imu at 200 Hz
while the robot stands, in ``camera_imu_frame``, whose axes are camera_link's: not the optical frame's)
and ``/camera/orientation`` (geometry_msgs/QuaternionStamped: the optical frame's orientation in
``base_link``, whose +z is up), ``/arm/camera_pose`` (geometry_msgs/PoseStamped: the optical frame in
``world`` as an arm reports it, off by a kinematic and hand-eye error per camera (``with_arm_error``); as the
gravity topic, it also gives the arm's pose hypotheses). ``--scene tabletop`` adds ``/camera/depth/image_raw``
(aligned depth, ``16UC1`` millimetres or ``32FC1`` metres) and ``/ground_truth/target_mask`` (``mono8``, the target's
true mask, for scoring segmentation). The robot stops at each view: /tf is sampled 0.1 s before and
after each image, so looking the camera up at the image stamp interpolates.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, QuaternionStamped, Vector3
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Image, Imu
from std_msgs.msg import Header
from tqdm import tqdm

from idpose_core.synthetic.catalogue import HELDOUT_BLOBS, heldout_objects
from idpose_core.synthetic.robot_views import LINK_FROM_OPTICAL, pinhole_intrinsics, robot_chain, with_arm_error
from idpose_core.synthetic.scenes import (
    FOV_DEG,
    ObjectSpec,
    SceneRenderer,
    demo_objects,
    random_camera_spheres,
    rolled_optical_frames,
    textured_objects,
)
from idpose_core.synthetic.tabletop import TabletopRenderer, random_layout, tabletop_cameras
from idpose_core.transforms import split_transform
from idpose_ros.evaluation.bag_io import TYPESTORE, BagError, BagWriter
from idpose_ros.evaluation.ground_truth import TRUE_MASK_TOPIC
from msg_adapters import array_to_image, depth_to_image, matrix_to_camera_info, matrix_to_pose

WORLD, BASE, LINK, OPTICAL, IMU = "world", "base_link", "camera_link", "camera_optical_frame", "camera_imu_frame"
IMAGE_TOPIC, INFO_TOPIC, POSE_TOPIC = "/camera/image_raw", "/camera/camera_info", "/camera/pose"
IMU_TOPIC, ORIENTATION_TOPIC, ARM_TOPIC = "/camera/imu", "/camera/orientation", "/arm/camera_pose"
DEPTH_TOPIC = "/camera/depth/image_raw"
START_NS = 100 * 1_000_000_000  # first view at t = 100 s
PERIOD_NS = 1_000_000_000  # one view per second
STOP_NS = 100_000_000  # the robot holds still 0.1 s either side of a view
IMU_PERIOD_NS = 5_000_000  # 200 Hz
IMU_NOISE = 0.05  # m/s^2, per axis and sample
GRAVITY = 9.80665
LINK_FROM_IMU = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, -0.01], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
OBJECT_SETS = {"demo": demo_objects, "heldout": lambda: heldout_objects(0, len(HELDOUT_BLOBS)),
               "textured": textured_objects}
"""The object sets a bag can show; ``heldout``: the catalogue's held-out objects, which no training run saw."""
SCENES = ("plain", "tabletop")
LIGHTS = ("random", "training")
TABLETOP_SIZE = 320  # px: the target covers about a sixth of the width


@dataclass(frozen=True)
class SyntheticBagOptions:
    """What a synthetic bag holds: ``views`` views of one object of ``object_set`` (``object_name``, default the
    set's first) on a ``scene``, cameras drawn from ``seed`` and each rolled by up to ``roll_deg``; images of
    ``size`` px (default 256 plain, ``TABLETOP_SIZE`` tabletop), depth as ``depth_format``, in ``storage``; a
    tabletop scene lit by a random lamp with shadows (``light`` "random") or by the white scenes' light ("training")."""

    storage: str = "mcap"
    object_set: str = "demo"
    object_name: str | None = None
    views: int = 12
    seed: int = 0
    size: int | None = None
    scene: str = "plain"
    roll_deg: float = 0.0
    depth_format: str = "16UC1"
    light: str = "random"

    def check(self) -> None:
        """BagError naming the first option out of range."""
        if self.scene not in SCENES:
            raise BagError(f"scene must be one of {', '.join(SCENES)}, got {self.scene!r}")
        if self.object_set not in OBJECT_SETS:
            raise BagError(f"object set must be one of {', '.join(OBJECT_SETS)}, got {self.object_set!r}")
        if self.views < 1:
            raise BagError(f"views must be at least 1, got {self.views}")
        if self.size is not None and self.size < 8:
            raise BagError(f"size must be at least 8 pixels, got {self.size}")
        if self.light not in LIGHTS:
            raise BagError(f"light must be one of {', '.join(LIGHTS)}, got {self.light!r}")
        if not 0.0 <= self.roll_deg <= 180.0:
            raise BagError(f"roll must be in [0, 180] degrees, got {self.roll_deg}")


@dataclass(frozen=True)
class Frame:
    """One rendered view: colour, depth in metres (tabletop; None on white, where the mask is the alpha channel)
    and the target's mask."""

    rgb: np.ndarray
    depth: np.ndarray | None
    target_mask: np.ndarray


def ros_time(stamp: int) -> Time:
    """Integer nanoseconds -> builtin_interfaces Time."""
    return Time(sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000)


def tf_message(stamp: int, links: list[tuple[str, str, np.ndarray]]) -> object:
    """A rosbags tf2_msgs/TFMessage of (parent, child, T_parent_child (4, 4)) links at ``stamp`` (ns)."""
    types = TYPESTORE.types
    transforms = []
    for parent, child, transform in links:
        (tx, ty, tz), (qx, qy, qz, qw) = split_transform(transform)
        transforms.append(types["geometry_msgs/msg/TransformStamped"](
            header=types["std_msgs/msg/Header"](
                stamp=types["builtin_interfaces/msg/Time"](sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000),
                frame_id=parent),
            child_frame_id=child,
            transform=types["geometry_msgs/msg/Transform"](
                translation=types["geometry_msgs/msg/Vector3"](x=tx, y=ty, z=tz),
                rotation=types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw)),
        ))
    return types["tf2_msgs/msg/TFMessage"](transforms=transforms)


def write_tf(bag: BagWriter, stamp: int, links: list[tuple[str, str, np.ndarray]], static: bool = False) -> None:
    """One TFMessage on /tf (or /tf_static), recorded at its stamp."""
    bag.write_message("/tf_static" if static else "/tf", "tf2_msgs/msg/TFMessage", stamp, tf_message(stamp, links))


def write_rgba_image(bag: BagWriter, topic: str, stamp: int, frame_id: str, rgb: np.ndarray, mask: np.ndarray
                     ) -> None:
    """An rgba8 sensor_msgs/Image whose alpha is the object mask."""
    rgba = np.dstack([rgb, np.where(mask, 255, 0).astype(np.uint8)])
    message = array_to_image(rgba, "rgba8", Header(frame_id=frame_id, stamp=ros_time(stamp)))
    bag.write(topic, "sensor_msgs/msg/Image", stamp, serialize_message(message))


def write_camera_info(bag: BagWriter, topic: str, stamp: int, frame_id: str, size: int, fov_deg: float) -> None:
    """A distortion-free sensor_msgs/CameraInfo of a square pinhole camera."""
    message = matrix_to_camera_info(pinhole_intrinsics(size, fov_deg), size, size,
                                    Header(frame_id=frame_id, stamp=ros_time(stamp)))
    bag.write(topic, "sensor_msgs/msg/CameraInfo", stamp, serialize_message(message))


def write_pose(bag: BagWriter, topic: str, stamp: int, frame_id: str, transform: np.ndarray) -> None:
    """A geometry_msgs/PoseStamped of ``transform`` (4, 4) in ``frame_id``."""
    message = PoseStamped(header=Header(frame_id=frame_id, stamp=ros_time(stamp)), pose=matrix_to_pose(transform))
    bag.write(topic, "geometry_msgs/msg/PoseStamped", stamp, serialize_message(message))


def write_imu(bag: BagWriter, stamp: int, world_from_imu: np.ndarray, rng: np.random.Generator) -> None:
    """Accelerometer samples at rest around ``stamp`` (the stop window): the floor's push, +g up, plus noise."""
    rotation = world_from_imu[:3, :3]
    for sample_stamp in range(stamp - STOP_NS, stamp + STOP_NS + 1, IMU_PERIOD_NS):
        a = rotation.T @ np.array([0.0, 0.0, GRAVITY]) + rng.normal(0.0, IMU_NOISE, size=3)
        message = Imu(header=Header(frame_id=IMU, stamp=ros_time(sample_stamp)),
                      linear_acceleration=Vector3(x=float(a[0]), y=float(a[1]), z=float(a[2])))
        message.orientation_covariance[0] = -1.0  # no orientation estimate (REP 145)
        bag.write(IMU_TOPIC, "sensor_msgs/msg/Imu", sample_stamp, serialize_message(message))


def write_orientation(bag: BagWriter, stamp: int, base_from_optical: np.ndarray) -> None:
    """The optical frame's orientation in base_link (whose +z is up), as an arm's kinematics would give it."""
    q = matrix_to_pose(base_from_optical).orientation
    message = QuaternionStamped(header=Header(frame_id=BASE, stamp=ros_time(stamp)), quaternion=q)
    bag.write(ORIENTATION_TOPIC, "geometry_msgs/msg/QuaternionStamped", stamp, serialize_message(message))


def write_image(bag: BagWriter, topic: str, stamp: int, message: Image) -> None:
    """An Image stamped and framed in the optical frame."""
    message.header = Header(frame_id=OPTICAL, stamp=ros_time(stamp))
    bag.write(topic, "sensor_msgs/msg/Image", stamp, serialize_message(message))


def render_frames(scene: str, spec: ObjectSpec, world_from_optical: np.ndarray, spheres: np.ndarray, rolls: np.ndarray,
                  size: int, rng: np.random.Generator, light: str = "random") -> list[Frame]:
    """Every view of the bag: the object alone on white, or on a table among others (layout drawn from ``rng``)."""
    if scene == "plain":
        with SceneRenderer(spec, image_size=size) as renderer:
            renders = [renderer.render(*sphere, roll=float(roll))
                       for sphere, roll in zip(tqdm(spheres, desc=f"rendering {spec.name}", unit="view"), rolls)]
        return [Frame(rgb, None, mask) for rgb, mask in renders]
    layout = random_layout(spec, rng, behind_azimuth=float(spheres[0, 1]), random_lighting=light == "random")
    with TabletopRenderer(layout, image_size=size, fov_deg=FOV_DEG) as renderer:
        renders = [renderer.render(frame) for frame in tqdm(world_from_optical, desc=f"rendering {spec.name}",
                                                              unit="view")]
    return [Frame(r.rgb, r.depth, r.target_mask) for r in renders]


def make_bag(out: Path, options: SyntheticBagOptions = SyntheticBagOptions()) -> Path:
    """Render the views ``options`` describe and write the bag; returns its path. BagError for bad options.

    Cameras look at the object centre (the world origin) from random directions: polar 30..150 deg at
    2 units on ``plain`` scenes, from above the table (polar 45..75 deg, 0.45..0.65 m) on ``tabletop``
    ones, each turned about its optical axis by a random angle within +-``roll_deg``.
    """
    options.check()
    storage, object_set, object_name, views, seed, size, scene, roll_deg, depth_format = (
        options.storage, options.object_set, options.object_name, options.views, options.seed, options.size,
        options.scene, options.roll_deg, options.depth_format)
    objects = OBJECT_SETS[object_set]()
    names = [spec.name for spec in objects]
    spec = objects[0] if object_name is None else next((s for s in objects if s.name == object_name), None)
    if spec is None:
        raise BagError(f"object {object_name!r} is not in the {object_set} set ({', '.join(names)})")
    rng = np.random.default_rng(seed)
    spheres = random_camera_spheres(rng, views) if scene == "plain" else tabletop_cameras(rng, views)
    rolls = np.radians(rng.uniform(-roll_deg, roll_deg, size=views)) if roll_deg > 0 else np.zeros(views)
    size = size or (256 if scene == "plain" else TABLETOP_SIZE)
    world_from_optical = rolled_optical_frames(spheres, rolls)
    frames = render_frames(scene, spec, world_from_optical, spheres, rolls, size, rng, options.light)
    noise, arm = np.random.default_rng([seed, 1]), np.random.default_rng([seed, 2])
    with BagWriter(out, storage) as bag:
        write_tf(bag, START_NS - STOP_NS, [(LINK, OPTICAL, LINK_FROM_OPTICAL), (LINK, IMU, LINK_FROM_IMU)],
                 static=True)
        for index, frame in enumerate(frames):
            stamp = START_NS + index * PERIOD_NS
            world_from_base, base_from_link = robot_chain(world_from_optical[index])
            for tf_stamp in (stamp - STOP_NS, stamp + STOP_NS):
                write_tf(bag, tf_stamp, [(WORLD, BASE, world_from_base), (BASE, LINK, base_from_link)])
            world_from_link = world_from_base @ base_from_link
            write_imu(bag, stamp, world_from_link @ LINK_FROM_IMU, noise)
            write_orientation(bag, stamp, base_from_link @ LINK_FROM_OPTICAL)
            if frame.depth is None:
                write_rgba_image(bag, IMAGE_TOPIC, stamp, OPTICAL, frame.rgb, frame.target_mask)
            else:
                write_image(bag, IMAGE_TOPIC, stamp, array_to_image(frame.rgb, "rgb8"))
                write_image(bag, DEPTH_TOPIC, stamp, depth_to_image(frame.depth, depth_format))
                write_image(bag, TRUE_MASK_TOPIC, stamp,
                            array_to_image(np.where(frame.target_mask, 255, 0).astype(np.uint8), "mono8"))
            write_camera_info(bag, INFO_TOPIC, stamp, OPTICAL, size, FOV_DEG)
            write_pose(bag, POSE_TOPIC, stamp, WORLD, world_from_optical[index])
            write_pose(bag, ARM_TOPIC, stamp, WORLD, with_arm_error(world_from_optical[index], arm))
    return out
