"""camera_markers: one frustum and one label per camera, placed at the camera pose, for RViz."""
import cv2
import numpy as np
import pytest
from builtin_interfaces.msg import Time
from rclpy.serialization import deserialize_message, serialize_message
from visualization_msgs.msg import Marker, MarkerArray

from msg_adapters import AdapterError, camera_markers, pose_to_matrix


def cameras() -> np.ndarray:
    """Three optical-frame camera poses: identity, and two rotated and moved ones."""
    poses = np.tile(np.eye(4), (3, 1, 1))
    poses[1, :3, :3] = cv2.Rodrigues(np.array([0.0, 0.5, 0.0]))[0]
    poses[1, :3, 3] = (0.4, 0.0, 0.1)
    poses[2, :3, :3] = cv2.Rodrigues(np.array([0.2, -1.0, 0.3]))[0]
    poses[2, :3, 3] = (-0.3, 0.2, 0.5)
    return poses


def points_in_frame(marker: Marker) -> np.ndarray:
    """The marker's points, (P, 3), in the header frame."""
    local = np.array([[p.x, p.y, p.z, 1.0] for p in marker.points])
    return (pose_to_matrix(marker.pose) @ local.T).T[:, :3]


def test_one_frustum_and_one_label_per_camera_after_a_clear():
    message = camera_markers(cameras(), "anchor_optical", Time(sec=4), labels=["anchor", "b", "c"])
    clear, *rest = message.markers
    assert clear.action == Marker.DELETEALL
    frusta = [m for m in rest if m.type == Marker.LINE_LIST]
    labels = [m for m in rest if m.type == Marker.TEXT_VIEW_FACING]
    assert [m.id for m in frusta] == [0, 1, 2] and [m.text for m in labels] == ["anchor", "b", "c"]
    assert len({(m.ns, m.id) for m in rest}) == len(rest) == 6
    assert all(m.header.frame_id == "anchor_optical" and m.header.stamp.sec == 4 for m in message.markers)
    assert all(len(m.points) % 2 == 0 and m.scale.x > 0 and m.color.a > 0 for m in frusta)


def test_frustum_apex_is_the_camera_centre_and_it_opens_along_the_optical_axis():
    depth, fov = 0.2, 60.0
    message = camera_markers(cameras(), "f", Time(), depth=depth, fov_deg=fov, aspect=1.5, clear=False)
    for camera, frustum in zip(cameras(), message.markers[0::2]):
        points = points_in_frame(frustum)
        centre, forward = camera[:3, 3], camera[:3, 2]
        along_axis = (points - centre) @ forward
        assert np.isclose(along_axis.min(), 0.0, atol=1e-12) and np.isclose(along_axis.max(), depth)
        right = (points - centre) @ camera[:3, 0]
        down = (points - centre) @ camera[:3, 1]
        half_width = depth * np.tan(np.radians(fov / 2))
        assert np.isclose(right.max(), half_width) and np.isclose(right.min(), -half_width)
        assert np.isclose(down.max(), half_width / 1.5)  # bottom edge of the image
        assert down.min() < -half_width / 1.5  # the "up" mark sits above the top edge (optical y points down)


def test_labels_default_to_view_numbers_and_sit_above_each_camera():
    message = camera_markers(cameras(), "f", Time(), clear=False)
    labels = message.markers[1::2]
    assert [m.text for m in labels] == ["view 0", "view 1", "view 2"]
    for camera, label in zip(cameras(), labels):
        offset = pose_to_matrix(label.pose)[:3, 3] - camera[:3, 3]
        assert offset @ camera[:3, 1] < 0  # camera up is -y in the optical frame


def test_marker_array_survives_serialisation():
    message = camera_markers(cameras(), "f", Time(sec=1))
    again = deserialize_message(serialize_message(message), MarkerArray)
    assert len(again.markers) == 7 and again.markers[1].points[1].z == message.markers[1].points[1].z


@pytest.mark.parametrize("kwargs, pattern", [
    (dict(labels=["a"]), r"labels has 1 entries; expected one per camera \(3\)"),
    (dict(depth=0.0), r"depth must be a positive finite length"),
    (dict(depth=float("nan")), r"depth must be a positive finite length"),
    (dict(fov_deg=180.0), r"fov_deg must be in \(0, 180\)"),
    (dict(fov_deg=float("nan")), r"fov_deg must be in \(0, 180\)"),
    (dict(aspect=-1.0), r"aspect must be a positive"),
    (dict(rgba=(1.0, 0.0, 0.0)), r"rgba must be 4 values in \[0, 1\]"),
    (dict(rgba=(1.0, 0.0, 0.0, 2.0)), r"rgba must be 4 values"),
])
def test_bad_marker_options_raise_adapter_error(kwargs, pattern):
    with pytest.raises(AdapterError, match=pattern):
        camera_markers(cameras(), "f", Time(), **kwargs)


def test_bad_camera_pose_is_named():
    poses = cameras()
    poses[1, :3, :3] *= -1
    with pytest.raises(AdapterError, match=r"Ts\[1\]\[:3, :3\] is not a rotation"):
        camera_markers(poses, "f", Time())
