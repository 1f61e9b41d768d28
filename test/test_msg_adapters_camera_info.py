"""CameraInfo -> K: a calibrated camera's matrix, clear errors for an uncalibrated or malformed one."""
import numpy as np
import pytest
from sensor_msgs.msg import CameraInfo

from msg_adapters import AdapterError, camera_info_to_matrix


def info(k) -> CameraInfo:
    return CameraInfo(width=640, height=480, k=[float(x) for x in k])


def test_a_calibrated_camera_gives_its_matrix():
    k = [500.0, 0.0, 320.0, 0.0, 510.0, 240.0, 0.0, 0.0, 1.0]
    matrix = camera_info_to_matrix(info(k))
    assert matrix.dtype == np.float64 and matrix.shape == (3, 3)
    np.testing.assert_array_equal(matrix.ravel(), k)


def test_uncalibrated_and_malformed_matrices_are_refused():
    with pytest.raises(AdapterError, match="uncalibrated"):
        camera_info_to_matrix(info([0.0] * 9))
    with pytest.raises(AdapterError, match="positive focal lengths"):
        camera_info_to_matrix(info([-500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0]))
    with pytest.raises(AdapterError, match="pinhole camera matrix"):
        camera_info_to_matrix(info([500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 2.0]))
