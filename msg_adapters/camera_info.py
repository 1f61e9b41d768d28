"""sensor_msgs/CameraInfo -> the camera matrix K, for methods that need intrinsics (the classical baselines)."""
import numpy as np
from sensor_msgs.msg import CameraInfo

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
