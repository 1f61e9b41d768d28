"""The node's next view seen by a real rclpy subscriber and action client: ~/next_view carries exactly the result's
next_view, in the anchor's frame and stamp, and the camera stands where the next_view_* parameters allow.

The model is the tiny random one, so which view is ambiguous is arbitrary; the checks are the geometry the
parameters fix (no gravity: world up is the level anchor's -y), not the choice among the allowed cameras.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from action_msgs.msg import GoalStatus
from geometry_msgs.msg import PoseStamped
from node_harness import ActionProbe, mixed_encodings
from sensor_msgs.msg import Image

from idpose_ros.node.result_publisher import RESULT_QOS
from msg_adapters import pose_to_matrix

pytestmark = pytest.mark.slow  # starts a node

DISTANCE = 0.8


def test_the_next_view_is_published_in_the_anchor_frame_within_reach(harness, object_views, wait_for):
    h = harness(capture_mode="on_request", object_distance=DISTANCE, next_view_polar_deg=[70.0, 80.0],
                next_view_azimuth_deg=[90.0, 150.0], next_view_distance=[0.1, 0.5])
    published: list[PoseStamped] = []
    h.probe.create_subscription(PoseStamped, "idpose_estimator/next_view", published.append, RESULT_QOS)
    images = [m for m in mixed_encodings(object_views) if isinstance(m, Image)][:3]
    status, result = ActionProbe(h).run(images)
    assert status == GoalStatus.STATUS_SUCCEEDED, result.error_message
    (message,) = wait_for(lambda: published, "the PoseStamped on ~/next_view")
    assert message == result.next_view, "the result holds what the topic publishes"
    assert message.header == result.poses.header, "the anchor's frame and stamp"
    assert 0.0 <= result.next_view_gain <= 1.0 and result.next_view_reason
    assert result.next_view_settles == -1 or result.views[result.next_view_settles].ambiguous

    pose = pose_to_matrix(message.pose)
    centre = np.array([0.0, 0.0, DISTANCE])  # the object, straight ahead of the anchor camera
    offset = pose[:3, 3] - centre
    assert np.linalg.norm(offset) == pytest.approx(0.5, abs=1e-6), "the anchor's distance clipped into reach"
    assert np.allclose(pose[:3, 3] + 0.5 * pose[:3, 2], centre, atol=1e-6), "looking at the object"
    up = np.array([0.0, -1.0, 0.0])  # the default anchor is level (polar 90), without gravity unrolled
    polar = math.degrees(math.acos(offset @ up / np.linalg.norm(offset)))
    azimuth = math.degrees(math.atan2(offset[0], -offset[2]))  # from the anchor's side of the object
    assert 70.0 - 1e-6 <= polar <= 80.0 + 1e-6
    assert 90.0 - 1e-6 <= abs(azimuth) <= 150.0 + 1e-6
    assert abs(pose[:3, 0] @ up) < 1e-6, "upright: its x axis is level"
