"""The arm's camera pose a view carries: a camera_pose message (the optical frame in a fixed frame) that gave the
view its gravity is also its pose for the arm's hypothesis; gravity from an Imu or a bare orientation gives none."""
import numpy as np
from geometry_msgs.msg import PoseStamped, QuaternionStamped
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import Imu

from idpose_ros.node.view_intake import arm_pose
from msg_adapters import matrix_to_pose


def test_a_camera_pose_message_is_the_views_arm_pose():
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_euler("xyz", [100.0, 5.0, 30.0], degrees=True).as_matrix()
    pose[:3, 3] = [0.4, -0.2, 0.9]
    np.testing.assert_allclose(arm_pose((PoseStamped(pose=matrix_to_pose(pose)),)), pose, atol=1e-9)


def test_gravity_from_an_imu_or_an_orientation_gives_no_arm_pose():
    assert arm_pose((Imu(), Imu())) is None
    assert arm_pose((QuaternionStamped(),)) is None
    assert arm_pose(()) is None
