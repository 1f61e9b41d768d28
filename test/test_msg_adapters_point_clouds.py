"""Coloured points <-> PointCloud2: the layout PCL and RViz read (x, y, z float32, rgb packed), both ways."""
import numpy as np
import pytest
from builtin_interfaces.msg import Time
from sensor_msgs.msg import PointField

from msg_adapters import AdapterError, cloud_to_points, points_to_cloud


def test_points_and_colours_survive_the_round_trip():
    rng = np.random.default_rng(0)
    points = rng.uniform(-1, 1, (100, 3))
    colours = rng.integers(0, 256, (100, 3), dtype=np.uint8)
    cloud = points_to_cloud(points, colours, "anchor_cam", Time(sec=42, nanosec=7))
    assert (cloud.header.frame_id, cloud.header.stamp.sec, cloud.header.stamp.nanosec) == ("anchor_cam", 42, 7)
    assert (cloud.height, cloud.width, cloud.point_step, cloud.row_step) == (1, 100, 16, 1600)
    assert [(f.name, f.offset, f.datatype) for f in cloud.fields] == [
        ("x", 0, PointField.FLOAT32), ("y", 4, PointField.FLOAT32), ("z", 8, PointField.FLOAT32),
        ("rgb", 12, PointField.FLOAT32)]
    back, back_colours = cloud_to_points(cloud)
    np.testing.assert_allclose(back, points, atol=1e-6)
    np.testing.assert_array_equal(back_colours, colours)


def test_rgb_is_packed_as_pcl_packs_it():
    cloud = points_to_cloud(np.zeros((1, 3)), np.array([[0x12, 0x34, 0x56]], np.uint8), "f", Time())
    assert int.from_bytes(bytes(cloud.data[12:16]), "little") == 0x123456


def test_an_empty_cloud_is_valid():
    cloud = points_to_cloud(np.zeros((0, 3)), np.zeros((0, 3), np.uint8), "f", Time())
    points, colours = cloud_to_points(cloud)
    assert cloud.width == 0 and points.shape == (0, 3) and colours.shape == (0, 3)


@pytest.mark.parametrize("points, colours, message", [
    (np.zeros((4, 2)), np.zeros((4, 3), np.uint8), r"points must have shape \(M, 3\)"),
    (np.zeros((4, 3)), np.zeros((4, 3), np.float32), "colours must be uint8"),
    (np.full((4, 3), np.nan), np.zeros((4, 3), np.uint8), "non-finite"),
])
def test_bad_points_are_refused_with_the_reason(points, colours, message):
    with pytest.raises(AdapterError, match=message):
        points_to_cloud(points, colours, "f", Time())


def test_a_cloud_of_another_layout_is_refused():
    cloud = points_to_cloud(np.zeros((2, 3)), np.zeros((2, 3), np.uint8), "f", Time())
    cloud.fields = cloud.fields[:3]
    with pytest.raises(AdapterError, match="expected a little-endian x, y, z, rgb float32 cloud"):
        cloud_to_points(cloud)
