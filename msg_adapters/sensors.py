"""What the robot knows about a view, from its messages: gravity (Imu) and the camera's orientation."""
import numpy as np
from geometry_msgs.msg import PoseStamped, QuaternionStamped
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import Imu

from msg_adapters.errors import AdapterError


def imu_acceleration(msg: Imu) -> np.ndarray:
    """linear_acceleration (3,) in the Imu's frame (m/s^2); AdapterError when not finite or zero."""
    a = msg.linear_acceleration
    vector = np.array([a.x, a.y, a.z], dtype=np.float64)
    if not np.all(np.isfinite(vector)) or np.linalg.norm(vector) < 1e-6:
        raise AdapterError(f"Imu.linear_acceleration has no direction: {vector.tolist()}")
    return vector


def orientation_rotation(msg: PoseStamped | QuaternionStamped) -> np.ndarray:
    """The rotation (3, 3) of a PoseStamped's or QuaternionStamped's orientation (position ignored)."""
    q = msg.pose.orientation if isinstance(msg, PoseStamped) else msg.quaternion
    quaternion = np.array([q.x, q.y, q.z, q.w], dtype=np.float64)
    if not np.all(np.isfinite(quaternion)) or np.linalg.norm(quaternion) < 1e-12:
        raise AdapterError(f"orientation {quaternion.tolist()} is not a rotation (x, y, z, w)")
    return Rotation.from_quat(quaternion).as_matrix()
