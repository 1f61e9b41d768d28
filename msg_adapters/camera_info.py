"""sensor_msgs/CameraInfo <-> the camera matrix K, for methods that need intrinsics (depth, the classical baselines)."""
import numpy as np
from sensor_msgs.msg import CameraInfo
from std_msgs.msg import Header

from msg_adapters.errors import AdapterError


def camera_info_to_matrix(msg: CameraInfo) -> np.ndarray:
    """K (3, 3) float64 of a calibrated camera; AdapterError for an uncalibrated one (K all zero, as drivers
    publish it) or a K that is not a pinhole matrix with positive focal lengths."""
    matrix = np.asarray(msg.k, dtype=np.float64).reshape(3, 3)
    if not matrix.any():
        raise AdapterError("CameraInfo.k is all zero: the camera is uncalibrated")
    if not (np.isfinite(matrix).all() and matrix[0, 0] > 0 and matrix[1, 1] > 0
            and np.array_equal(matrix[2], [0.0, 0.0, 1.0]) and matrix[1, 0] == 0):
        raise AdapterError(f"CameraInfo.k = {matrix.ravel().tolist()} is not a pinhole camera matrix "
                           "[fx, s, cx, 0, fy, cy, 0, 0, 1] with positive focal lengths")
    return matrix


def matrix_to_camera_info(matrix: np.ndarray, width: int, height: int, header: Header | None = None) -> CameraInfo:
    """A distortion-free CameraInfo of a pinhole camera with matrix K (3, 3) for ``width`` x ``height`` images."""
    k = np.asarray(matrix, dtype=np.float64).reshape(3, 3)
    return CameraInfo(header=header if header is not None else Header(), height=int(height), width=int(width),
                      distortion_model="plumb_bob", d=[0.0] * 5, k=k.ravel().tolist(), r=np.eye(3).ravel().tolist(),
                      p=np.hstack([k, np.zeros((3, 1))]).ravel().tolist())
