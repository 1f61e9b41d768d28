"""RViz camera frusta: one LINE_LIST frustum and one text label per camera pose."""
import numpy as np
from geometry_msgs.msg import Point, Pose, Vector3
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from msg_adapters.errors import AdapterError
from msg_adapters.headers import make_header
from msg_adapters.poses import check_transforms, matrix_to_pose


def frustum_half_size(depth: float, fov_deg: float, aspect: float) -> tuple[float, float]:
    """Half width and half height of the image rectangle at `depth` (horizontal fov, aspect = width / height)."""
    half_width = depth * np.tan(np.radians(fov_deg) / 2)
    return half_width, half_width / aspect


def frustum_segments(depth: float, fov_deg: float, aspect: float) -> np.ndarray:
    """(20, 3) LINE_LIST end points of a frustum in the optical frame (x right, y down, z forward).

    Apex-to-corner edges, the image rectangle at `depth`, and a triangle on the top edge marking "up".
    """
    half_w, half_h = frustum_half_size(depth, fov_deg, aspect)
    apex = np.zeros(3)
    top_left, top_right = np.array([-half_w, -half_h, depth]), np.array([half_w, -half_h, depth])
    bottom_right, bottom_left = np.array([half_w, half_h, depth]), np.array([-half_w, half_h, depth])
    corners = [top_left, top_right, bottom_right, bottom_left]
    up_tip = np.array([0.0, -half_h - 0.6 * half_h, depth])
    up_left, up_right = np.array([-0.5 * half_w, -half_h, depth]), np.array([0.5 * half_w, -half_h, depth])
    segments = [(apex, corner) for corner in corners]
    segments += [(corners[i], corners[(i + 1) % 4]) for i in range(4)]
    segments += [(up_left, up_tip), (up_tip, up_right)]
    return np.array([point for segment in segments for point in segment])


def camera_markers(
    transforms,
    frame_id: str,
    stamp,
    *,
    labels: list[str] | None = None,
    depth: float = 0.1,
    fov_deg: float = 50.0,
    aspect: float = 1.0,
    rgba: tuple[float, float, float, float] = (0.1, 0.6, 1.0, 1.0),
    namespace: str = "cameras",
    clear: bool = True,
) -> MarkerArray:
    """MarkerArray drawing each (4, 4) optical-frame camera pose in `transforms` (N, 4, 4) as a frustum.

    Markers: an optional DELETEALL first (so cameras from an earlier, larger set disappear), then per
    camera i a LINE_LIST (namespace `namespace`, id i) and a TEXT_VIEW_FACING label
    (namespace `namespace`_labels, id i) above the frustum; labels default to "view i".
    """
    stack = check_transforms(transforms)
    if labels is None:
        labels = [f"view {index}" for index in range(len(stack))]
    if len(labels) != len(stack):
        raise AdapterError(f"labels has {len(labels)} entries; expected one per camera ({len(stack)})")
    if not (np.isfinite(depth) and depth > 0):
        raise AdapterError(f"depth must be a positive finite length, got {depth}")
    if not (0 < fov_deg < 180):
        raise AdapterError(f"fov_deg must be in (0, 180), got {fov_deg}")
    if not (np.isfinite(aspect) and aspect > 0):
        raise AdapterError(f"aspect must be a positive width / height ratio, got {aspect}")
    if len(rgba) != 4 or not all(0.0 <= float(value) <= 1.0 for value in rgba):
        raise AdapterError(f"rgba must be 4 values in [0, 1], got {rgba}")
    header = make_header(frame_id, stamp)
    colour = ColorRGBA(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]), a=float(rgba[3]))
    points = [Point(x=x, y=y, z=z) for x, y, z in frustum_segments(depth, fov_deg, aspect).tolist()]
    label_offset = np.array([0.0, -2.0 * frustum_half_size(depth, fov_deg, aspect)[1], depth, 1.0])
    markers = [Marker(header=header, ns=namespace, action=Marker.DELETEALL)] if clear else []
    for index, (matrix, label) in enumerate(zip(stack, labels)):
        markers.append(Marker(
            header=header, ns=namespace, id=index, type=Marker.LINE_LIST, action=Marker.ADD,
            pose=matrix_to_pose(matrix), scale=Vector3(x=0.02 * depth), color=colour, points=points,
        ))
        x, y, z = (matrix @ label_offset)[:3].tolist()
        markers.append(Marker(
            header=header, ns=f"{namespace}_labels", id=index, type=Marker.TEXT_VIEW_FACING,
            action=Marker.ADD, pose=Pose(position=Point(x=x, y=y, z=z)), scale=Vector3(z=0.3 * depth),
            color=ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0), text=str(label),
        ))
    return MarkerArray(markers=markers)


def box_marker(pose, size, frame_id: str, stamp, *, namespace: str = "object", marker_id: int = 0,
               rgba: tuple[float, float, float, float] = (1.0, 0.6, 0.1, 0.35)) -> Marker:
    """A translucent CUBE marker: the box of sides ``size`` (3,) metres at ``pose`` (4, 4)."""
    sides = np.asarray(size, dtype=np.float64)
    if sides.shape != (3,) or not (np.isfinite(sides).all() and (sides >= 0).all()):
        raise AdapterError(f"size must be 3 non-negative lengths, got {sides.tolist()}")
    return Marker(header=make_header(frame_id, stamp), ns=namespace, id=marker_id, type=Marker.CUBE,
                  action=Marker.ADD, pose=matrix_to_pose(pose), scale=Vector3(x=sides[0], y=sides[1], z=sides[2]),
                  color=ColorRGBA(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]), a=float(rgba[3])))
