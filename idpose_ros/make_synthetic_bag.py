"""`make_synthetic_bag OUT`: render pybullet views of an object from random cameras into a real rosbag2.

Topics: ``/camera/image_raw`` (sensor_msgs/Image rgba8, alpha = object mask), ``/camera/camera_info``,
``/camera/pose`` (geometry_msgs/PoseStamped, the optical frame in ``world``: ground truth for
``--gt-topic``), ``/tf`` (world -> base_link -> camera_link, the robot moving between views) and
``/tf_static`` (camera_link -> camera_optical_frame). The robot stops at each view: /tf is sampled
0.1 s before and after each image, so looking the camera up at the image stamp interpolates.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from rclpy.serialization import serialize_message
from sensor_msgs.msg import CameraInfo
from std_msgs.msg import Header
from tqdm import tqdm

from idpose_core.cameras import opengl_to_optical, spherical_to_c2w
from idpose_core.synthetic.robot_views import LINK_FROM_OPTICAL, pinhole_intrinsics, robot_chain
from idpose_core.synthetic.scenes import (
    FOV_DEG,
    SceneRenderer,
    demo_objects,
    random_camera_spheres,
    textured_objects,
    unseen_objects,
)
from idpose_core.transforms import split_transform
from idpose_ros.bag_io import TYPESTORE, BagError, BagWriter
from msg_adapters import array_to_image, matrix_to_pose

WORLD, BASE, LINK, OPTICAL = "world", "base_link", "camera_link", "camera_optical_frame"
IMAGE_TOPIC, INFO_TOPIC, POSE_TOPIC = "/camera/image_raw", "/camera/camera_info", "/camera/pose"
START_NS = 100 * 1_000_000_000  # first view at t = 100 s
PERIOD_NS = 1_000_000_000  # one view per second
STOP_NS = 100_000_000  # the robot holds still 0.1 s either side of a view
OBJECT_SETS = {"demo": demo_objects, "unseen": unseen_objects, "textured": textured_objects}


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
    k = pinhole_intrinsics(size, fov_deg)
    projection = np.hstack([k, np.zeros((3, 1))])
    message = CameraInfo(header=Header(frame_id=frame_id, stamp=ros_time(stamp)), height=size, width=size,
                         distortion_model="plumb_bob", d=[0.0] * 5, k=k.ravel().tolist(),
                         r=np.eye(3).ravel().tolist(), p=projection.ravel().tolist())
    bag.write(topic, "sensor_msgs/msg/CameraInfo", stamp, serialize_message(message))


def write_pose(bag: BagWriter, topic: str, stamp: int, frame_id: str, transform: np.ndarray) -> None:
    """A geometry_msgs/PoseStamped of ``transform`` (4, 4) in ``frame_id``."""
    message = PoseStamped(header=Header(frame_id=frame_id, stamp=ros_time(stamp)), pose=matrix_to_pose(transform))
    bag.write(topic, "geometry_msgs/msg/PoseStamped", stamp, serialize_message(message))


def make_bag(out: Path, storage: str, object_set: str, object_name: str | None, views: int, seed: int,
             size: int) -> Path:
    """Render ``views`` views of one object and write the bag; returns its path."""
    objects = OBJECT_SETS[object_set]()
    names = [spec.name for spec in objects]
    spec = objects[0] if object_name is None else next((s for s in objects if s.name == object_name), None)
    if spec is None:
        raise BagError(f"object {object_name!r} is not in the {object_set} set ({', '.join(names)})")
    spheres = random_camera_spheres(np.random.default_rng(seed), views)
    world_from_optical = opengl_to_optical(spherical_to_c2w(spheres))
    with SceneRenderer(spec, image_size=size) as renderer, BagWriter(out, storage) as bag:
        write_tf(bag, START_NS - STOP_NS, [(LINK, OPTICAL, LINK_FROM_OPTICAL)], static=True)
        for index in tqdm(range(views), desc=f"rendering {spec.name}", unit="view"):
            stamp = START_NS + index * PERIOD_NS
            world_from_base, base_from_link = robot_chain(world_from_optical[index])
            for tf_stamp in (stamp - STOP_NS, stamp + STOP_NS):
                write_tf(bag, tf_stamp, [(WORLD, BASE, world_from_base), (BASE, LINK, base_from_link)])
            rgb, mask = renderer.render(*spheres[index])
            write_rgba_image(bag, IMAGE_TOPIC, stamp, OPTICAL, rgb, mask)
            write_camera_info(bag, INFO_TOPIC, stamp, OPTICAL, size, FOV_DEG)
            write_pose(bag, POSE_TOPIC, stamp, WORLD, world_from_optical[index])
    return out


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="make_synthetic_bag", description=__doc__.split("\n\n")[0].split(": ", 1)[1])
    parser.add_argument("out", type=Path, help="bag folder to create (must not exist)")
    parser.add_argument("--storage", choices=("sqlite3", "mcap"), default="mcap")
    parser.add_argument("--objects", choices=tuple(OBJECT_SETS), default="demo", help="object set")
    parser.add_argument("--object", default=None, help="object name in the set (default: the first)")
    parser.add_argument("--views", type=int, default=12, help="number of views (default 12)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random cameras")
    parser.add_argument("--size", type=int, default=256, help="image width and height in pixels")
    args = parser.parse_args(argv)
    if args.views < 1:
        parser.error(f"--views must be at least 1, got {args.views}")
    if args.size < 8:
        parser.error(f"--size must be at least 8 pixels, got {args.size}")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        out = make_bag(args.out, args.storage, args.objects, args.object, args.views, args.seed, args.size)
    except BagError as err:
        print(f"make_synthetic_bag: {err}", file=sys.stderr)
        return 2
    print(f"wrote {out} ({args.storage}, {args.views} views)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
