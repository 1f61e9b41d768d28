"""Active capture with a simulated arm: capture, estimate, move the camera where the node says to look next, repeat.

Start the node with on-request capture and the simulated camera's distance (``-p capture_mode:=on_request -p
object_distance:=2.0``; ``-p model_path:=training/novel_objects`` for the model trained on many objects), then
``python examples/active_capture.py --views 4``. A pybullet object (a held-out benchmark object by default) stands
at the origin of the arm's world, +z up; the camera starts at two random cameras around it. For each view the
arm publishes its camera's pose (``camera_pose``: the optical frame in the arm's world, which gives gravity) and
the render (``image``, the mask as alpha), and keeps it with ``~/capture``. From two views on it sends a goal on
the buffered views and turns the result's ``next_view`` (in the anchor camera's frame) into the arm's world
through the anchor camera's pose, where the arm goes next, until no view is ambiguous or the view budget is spent
(``--keep-going``: spend it all). It prints each suggestion, and at the end each view's rotation error against
the truth the arm knows.
"""
import argparse
import math
import sys
import time

import numpy as np
import rclpy
from geometry_msgs.msg import PoseStamped
from rclpy.action import ActionClient
from rclpy.node import Node
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import Image
from std_msgs.msg import Header
from std_srvs.srv import Trigger

from idpose_core.cameras import opengl_to_optical, spherical_to_c2w
from idpose_core.metrics import rotation_angle_deg
from idpose_core.spherical import cartesian_to_spherical
from idpose_core.synthetic.catalogue import BENCH_HELDOUT, heldout_objects
from idpose_core.synthetic.scenes import CAMERA_RADIUS, SceneRenderer
from idpose_interfaces.action import EstimatePoses
from msg_adapters import array_to_image, matrix_to_pose, pose_to_matrix

FRAME = "camera_optical"
SETTLE_S = 0.3  # s the arm publishes its pose before it asks ~/capture for the view


def camera_at(polar_deg: float, azimuth_deg: float) -> np.ndarray:
    """The optical frame (4, 4) in the arm's world of an upright camera looking at the origin."""
    sphere = np.array([math.radians(polar_deg), math.radians(azimuth_deg), CAMERA_RADIUS])
    return opengl_to_optical(spherical_to_c2w(sphere))


class SimulatedArm:
    """Renders the object from a camera pose and hands the view to the estimator node."""

    def __init__(self, node: Node, renderer: SceneRenderer) -> None:
        self.node, self.renderer = node, renderer
        self.images = node.create_publisher(Image, "image", 10)
        self.poses = node.create_publisher(PoseStamped, "camera_pose", 10)
        self.capture = node.create_client(Trigger, "idpose_estimator/capture")
        self.capture.wait_for_service()
        while self.images.get_subscription_count() == 0 or self.poses.get_subscription_count() == 0:
            rclpy.spin_once(node, timeout_sec=0.1)

    def take(self, world_from_camera: np.ndarray) -> str:
        """Render from the camera, publish its pose and image under one stamp until ``~/capture`` keeps it."""
        polar, azimuth, radius = cartesian_to_spherical(world_from_camera[:3, 3])
        rgb, mask = self.renderer.render(polar, azimuth, radius)
        header = Header(frame_id=FRAME, stamp=self.node.get_clock().now().to_msg())
        image = array_to_image(np.dstack([rgb, (mask * 255).astype(np.uint8)]), "rgba8", header)
        pose = PoseStamped(header=Header(frame_id="world", stamp=header.stamp), pose=matrix_to_pose(world_from_camera))
        while True:
            self.poses.publish(pose)
            self.images.publish(image)
            # Keep publishing the pose a moment before asking: a view takes the gravity and the pose the node holds
            # for its stamp when it is kept, and the node may take the image before the pose.
            settled = time.monotonic() + SETTLE_S
            while time.monotonic() < settled:
                self.poses.publish(pose)
                rclpy.spin_once(self.node, timeout_sec=0.02)
            future = self.capture.call_async(Trigger.Request())
            rclpy.spin_until_future_complete(self.node, future)
            if future.result().success:
                return future.result().message


def estimate(node: Node, action: ActionClient) -> EstimatePoses.Result:
    """One goal on the buffered views; its result."""
    sent = action.send_goal_async(EstimatePoses.Goal())
    rclpy.spin_until_future_complete(node, sent)
    finished = sent.result().get_result_async()
    rclpy.spin_until_future_complete(node, finished)
    return finished.result().result


def main() -> int:
    rclpy.init(args=sys.argv)
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--views", type=int, default=4, help="the view budget")
    parser.add_argument("--keep-going", action="store_true", help="spend the budget even when nothing is ambiguous")
    parser.add_argument("--object", type=int, default=0, help="which held-out benchmark object")
    parser.add_argument("--seed", type=int, default=0, help="the two starting cameras")
    args = parser.parse_args(remove_ros_args(sys.argv)[1:])
    rng = np.random.default_rng(args.seed)
    node = Node("active_capture")
    action = ActionClient(node, EstimatePoses, "idpose_estimator/estimate_poses")
    action.wait_for_server()
    spec = heldout_objects(*BENCH_HELDOUT)[args.object]
    cameras = [camera_at(rng.uniform(50.0, 90.0), 0.0), camera_at(rng.uniform(50.0, 90.0), rng.uniform(40.0, 140.0))]
    with SceneRenderer(spec, image_size=256) as renderer:
        arm = SimulatedArm(node, renderer)
        for camera in cameras:
            print(arm.take(camera))
        while True:
            result = estimate(node, action)
            if result.error_code != EstimatePoses.Result.SUCCEEDED:
                print(f"run {result.run_id} failed (error code {result.error_code}): {result.error_message}")
                return 1
            ambiguous = [k for k, view in enumerate(result.views) if view.ambiguous]
            print(f"run {result.run_id}: {len(result.views)} views, ambiguous {ambiguous or 'none'}; next view: "
                  f"{result.next_view_reason} (gain {result.next_view_gain:.2f})")
            if len(cameras) >= args.views or not (ambiguous or args.keep_going):
                break
            cameras.append(cameras[0] @ pose_to_matrix(result.next_view.pose))  # anchor frame -> the arm's world
            print(arm.take(cameras[-1]))
    truth = [np.linalg.inv(cameras[0]) @ camera for camera in cameras]
    for k, (view, true_pose) in enumerate(zip(result.views, truth)):
        error = rotation_angle_deg(pose_to_matrix(view.pose)[:3, :3], true_pose[:3, :3])
        print(f"view {k}: rotation error {error:.1f} deg" + (", ambiguous" if view.ambiguous else ""))
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
