"""The node's depth outputs seen by a real rclpy subscriber and client: after an estimate on tabletop views with depth
and intrinsics, ~/object_cloud and ~/object_pose carry the object in the anchor's frame, its box is among the
markers, and the action result holds the same cloud and each view's depth fields.

The model is the tiny random one (its poses are noise): the anchor's own points make the cloud whatever the other
view's registration gives, so the cloud's place is checked against the rendered truth.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from action_msgs.msg import GoalStatus
from geometry_msgs.msg import PoseStamped
from node_harness import ActionProbe, header
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from visualization_msgs.msg import Marker

from idpose_core.cameras import pinhole_camera_matrix
from idpose_core.metrics import rotation_angle_deg
from idpose_core.pose_hypotheses import VerificationSettings
from idpose_core.synthetic.scenes import demo_objects
from idpose_core.synthetic.tabletop import TabletopRenderer, challenge_camera, random_layout
from idpose_ros.node.result_publisher import RESULT_QOS
from msg_adapters import array_to_image, cloud_to_points, matrix_to_camera_info, matrix_to_pose, pose_to_matrix

pytestmark = pytest.mark.slow  # starts a node

SIZE, FOV = 96, 60.0
CAMERAS = np.radians([[60.0, 20.0], [55.0, 70.0]])
DISTANCE = 0.55


@pytest.fixture(scope="module")
def tabletop():
    """Two renders of the lego brick on its table: (rgb, depth, mask) each, and the cameras (optical-to-world)."""
    lego = next(spec for spec in demo_objects() if spec.name == "lego")
    cameras = [challenge_camera(np.array([polar, azimuth, DISTANCE])) for polar, azimuth in CAMERAS]
    with TabletopRenderer(random_layout(lego, np.random.default_rng(5), 0.0), SIZE, FOV) as renderer:
        frames = [renderer.render(camera) for camera in cameras]
    return frames, cameras


def capture_with_depth(h, wait_for, frames, images: list[Image], arm_poses=None) -> None:
    """Publish the intrinsics, then per frame its depth (and, given ``arm_poses``, its optical frame in the world on
    camera_pose) and its image, stamped alike, and capture it; return once every view has its depth."""
    depth = h.probe.create_publisher(Image, "depth", 10)
    info = h.probe.create_publisher(CameraInfo, "camera_info", 10)
    arm = h.probe.create_publisher(PoseStamped, "camera_pose", 10)
    wait_for(lambda: depth.get_subscription_count() and info.get_subscription_count() and arm.get_subscription_count(),
             "the input subscriptions")
    info.publish(matrix_to_camera_info(pinhole_camera_matrix(SIZE, SIZE, FOV), SIZE, SIZE, header("cam", 1)))
    for k, (frame, image) in enumerate(zip(frames, images)):
        stamp = header("cam", 10 + k)
        if arm_poses is not None:
            arm.publish(PoseStamped(header=stamp, pose=matrix_to_pose(arm_poses[k])))
        depth.publish(array_to_image(frame.depth, "32FC1", stamp))
        image.header = stamp
        before = h.node.status().images_received
        h.send(image)
        wait_for(lambda before=before: h.node.status().images_received == before + 1, "the image")
        assert h.call("capture").success
    wait_for(lambda: all(view.input.depth is not None for view in h.node._buffer.snapshot()), "every depth image")


def test_an_estimate_with_depth_publishes_the_object(harness, tabletop, wait_for):
    frames, cameras = tabletop
    h = harness(capture_mode="on_request")
    clouds: list[PointCloud2] = []
    poses: list[PoseStamped] = []
    h.probe.create_subscription(PointCloud2, "idpose_estimator/object_cloud", clouds.append, RESULT_QOS)
    h.probe.create_subscription(PoseStamped, "idpose_estimator/object_pose", poses.append, RESULT_QOS)
    with_alpha = [np.dstack([frame.rgb, (frame.target_mask * 255).astype(np.uint8)]) for frame in frames]
    capture_with_depth(h, wait_for, frames, [array_to_image(rgba, "rgba8") for rgba in with_alpha])

    status, result = ActionProbe(h).run()
    assert status == GoalStatus.STATUS_SUCCEEDED, result.error_message
    (cloud,) = wait_for(lambda: clouds, "the object cloud")
    (pose,) = wait_for(lambda: poses, "the object pose")
    assert cloud == result.object_cloud and pose == result.object_pose, "the result holds what the topics publish"
    assert cloud.header == result.poses.header and pose.header == result.poses.header
    points, colours = cloud_to_points(cloud)
    truth = np.linalg.inv(cameras[0])[:3, 3]  # the object's centre (the world origin) in the anchor's frame
    assert len(points) > 50 and colours.dtype == np.uint8
    assert np.linalg.norm(points - truth, axis=1).max() < 0.12, "every point on the 20 cm object"
    assert np.linalg.norm(pose_to_matrix(pose.pose)[:3, 3] - truth) < 0.05
    assert result.object_axes == "anchor" and 0.05 < result.object_size.x < 0.25
    anchor, other = result.views
    assert (anchor.depth_refined, anchor.depth_note) == (False, "the anchor") and math.isnan(anchor.depth_fitness)
    assert other.depth_refined, "depth_poses verify: the verifier chose the pose of a view with depth"
    assert 0.0 <= other.depth_fitness <= 1.0
    assert other.pose_source in {"diffusion", "registration", "gravity"} and math.isfinite(other.verifier_margin)
    no_gravity_margin = VerificationSettings().ambiguity_margin_without_gravity  # no view here knows gravity
    assert other.ambiguous == (other.verifier_margin < no_gravity_margin)
    assert not other.object_moved and anchor.pose_source == "diffusion" and math.isnan(anchor.verifier_margin)
    markers = wait_for(lambda: h.markers, "the markers")[-1].markers
    (box,) = [marker for marker in markers if marker.type == Marker.CUBE]
    assert box.pose == pose.pose and box.header == pose.header


def test_the_arms_camera_pose_poses_a_view_with_depth(harness, tabletop, wait_for):
    """Each view's camera_pose (its optical frame in the world, z up) gives the node gravity and the arm's pose
    hypothesis: the verified pose of the second view is the camera's true pose, whatever the random model says."""
    frames, cameras = tabletop
    h = harness(capture_mode="on_request")
    capture_with_depth(h, wait_for, frames, [array_to_image(frame.rgb, "rgb8") for frame in frames], cameras)
    assert all(view.input.camera_pose is not None for view in h.node._buffer.snapshot())

    status, result = ActionProbe(h).run()
    assert status == GoalStatus.STATUS_SUCCEEDED, result.error_message
    other = result.views[1]
    truth = np.linalg.inv(cameras[0]) @ cameras[1]
    turn = rotation_angle_deg(pose_to_matrix(other.pose)[:3, :3], truth[:3, :3])
    assert other.depth_refined and other.polar_source == "gravity" and turn < 2.0
    assert not other.object_moved and math.isfinite(other.verifier_margin)
