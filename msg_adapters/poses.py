"""4x4 rigid transforms <-> geometry_msgs Pose and PoseArray."""
import numpy as np
from geometry_msgs.msg import Point, Pose, PoseArray, Quaternion
from scipy.spatial.transform import Rotation

from msg_adapters.errors import AdapterError
from msg_adapters.headers import make_header

# Tolerance on orthonormality and the bottom row: accepts transforms computed in float32.
RIGID_TOLERANCE = 1e-5


def as_float64(value, name: str) -> np.ndarray:
    """`value` as a float64 array, or AdapterError naming `name` when it is not numeric."""
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise AdapterError(f"{name} must be a numeric array: {error}") from error


def check_rigid(transform, name: str = "T") -> np.ndarray:
    """`transform` as a float64 (4, 4) array, or AdapterError unless it is a finite proper rigid transform."""
    matrix = as_float64(transform, name)
    if matrix.shape != (4, 4):
        raise AdapterError(f"{name} must have shape (4, 4), got {matrix.shape}")
    if not np.isfinite(matrix).all():
        raise AdapterError(f"{name} has non-finite entries; expected a finite rigid transform")
    if np.abs(matrix[3] - [0.0, 0.0, 0.0, 1.0]).max() > RIGID_TOLERANCE:
        raise AdapterError(f"{name} bottom row is {matrix[3].tolist()}; expected [0, 0, 0, 1]")
    rotation = matrix[:3, :3]
    orthonormality_error = np.abs(rotation.T @ rotation - np.eye(3)).max()
    if orthonormality_error > RIGID_TOLERANCE or np.linalg.det(rotation) < 0:
        raise AdapterError(
            f"{name}[:3, :3] is not a rotation (|R^T R - I| = {orthonormality_error:.3g}, "
            f"det = {np.linalg.det(rotation):.6g}); expected orthonormal with det +1"
        )
    return matrix


def matrix_to_pose(transform) -> Pose:
    """(4, 4) rigid transform -> Pose with a unit quaternion, signed canonically (w > 0, or at a half turn the first
    non-zero of x, y, z positive)."""
    matrix = check_rigid(transform)
    x, y, z, w = Rotation.from_matrix(matrix[:3, :3]).as_quat(canonical=True)
    tx, ty, tz = matrix[:3, 3]
    return Pose(position=Point(x=tx, y=ty, z=tz), orientation=Quaternion(x=x, y=y, z=z, w=w))


def pose_to_matrix(pose: Pose) -> np.ndarray:
    """Pose -> (4, 4) float64 transform; a non-unit quaternion is normalised, a zero one is an error."""
    p, o = pose.position, pose.orientation
    translation = np.array([p.x, p.y, p.z])
    quaternion = np.array([o.x, o.y, o.z, o.w])
    if not (np.isfinite(translation).all() and np.isfinite(quaternion).all()):
        raise AdapterError(f"Pose has non-finite values: position {translation.tolist()}, "
                           f"orientation {quaternion.tolist()}")
    if np.linalg.norm(quaternion) < 1e-12:
        raise AdapterError("Pose.orientation has zero norm; expected a unit quaternion (x, y, z, w)")
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_quat(quaternion).as_matrix()
    matrix[:3, 3] = translation
    return matrix


def check_transforms(transforms, name: str = "Ts") -> np.ndarray:
    """`transforms` as a float64 (N, 4, 4) array of rigid transforms, or AdapterError naming the bad one."""
    stack = as_float64(transforms, name)
    if stack.ndim != 3 or stack.shape[1:] != (4, 4):
        raise AdapterError(f"{name} must have shape (N, 4, 4), got {stack.shape}")
    for index, matrix in enumerate(stack):
        check_rigid(matrix, f"{name}[{index}]")
    return stack


def poses_to_pose_array(transforms, frame_id: str, stamp) -> PoseArray:
    """(N, 4, 4) transforms -> PoseArray in `frame_id` at `stamp` (builtin_interfaces Time or rclpy Time)."""
    stack = check_transforms(transforms)
    return PoseArray(header=make_header(frame_id, stamp), poses=[matrix_to_pose(matrix) for matrix in stack])
