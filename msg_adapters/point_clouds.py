"""Coloured points <-> sensor_msgs/PointCloud2 (x, y, z float32 and rgb packed in a float32, as PCL and RViz read it).

A ROS installation has ``sensor_msgs_py.point_cloud2`` for this; it ships in no PyPI wheel, so the packing is done
here with a numpy structured dtype, the same layout.
"""
import numpy as np
from sensor_msgs.msg import PointCloud2, PointField

from msg_adapters.errors import AdapterError
from msg_adapters.headers import make_header

CLOUD_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])
FIELDS = [PointField(name=name, offset=CLOUD_DTYPE.fields[name][1], datatype=PointField.FLOAT32, count=1)
          for name in ("x", "y", "z", "rgb")]


def points_to_cloud(points, colours, frame_id: str, stamp) -> PointCloud2:
    """An unordered PointCloud2 (height 1) of ``points`` (M, 3) metres with ``colours`` (M, 3) uint8 RGB."""
    xyz = np.asarray(points, dtype=np.float64)
    rgb = np.asarray(colours)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise AdapterError(f"points must have shape (M, 3), got {xyz.shape}")
    if rgb.shape != xyz.shape or rgb.dtype != np.uint8:
        raise AdapterError(f"colours must be uint8 with the points' shape {xyz.shape}, got {rgb.dtype} {rgb.shape}")
    if not np.isfinite(xyz).all():
        raise AdapterError("points has non-finite coordinates")
    packed = np.empty(len(xyz), dtype=CLOUD_DTYPE)
    packed["x"], packed["y"], packed["z"] = xyz.T.astype(np.float32)
    rgb32 = rgb.astype(np.uint32)
    packed["rgb"] = (rgb32[:, 0] << 16) | (rgb32[:, 1] << 8) | rgb32[:, 2]
    return PointCloud2(header=make_header(frame_id, stamp), height=1, width=len(xyz), fields=FIELDS,
                       is_bigendian=False, point_step=CLOUD_DTYPE.itemsize, row_step=CLOUD_DTYPE.itemsize * len(xyz),
                       data=packed.tobytes(), is_dense=True)


def cloud_to_points(cloud: PointCloud2) -> tuple[np.ndarray, np.ndarray]:
    """(points (M, 3) float64 metres, colours (M, 3) uint8) of a PointCloud2 laid out as ``points_to_cloud``
    writes it; AdapterError for any other layout."""
    names = [(field.name, field.offset, field.datatype) for field in cloud.fields]
    expected = [(field.name, field.offset, field.datatype) for field in FIELDS]
    if names != expected or cloud.point_step != CLOUD_DTYPE.itemsize or cloud.is_bigendian:
        raise AdapterError(f"expected a little-endian x, y, z, rgb float32 cloud of point_step "
                           f"{CLOUD_DTYPE.itemsize}, got fields {names}, point_step {cloud.point_step}")
    count = cloud.width * cloud.height
    if len(cloud.data) != count * CLOUD_DTYPE.itemsize:
        raise AdapterError(f"cloud data holds {len(cloud.data)} bytes, expected {count * CLOUD_DTYPE.itemsize}")
    packed = np.frombuffer(bytes(cloud.data), dtype=CLOUD_DTYPE)
    points = np.stack([packed["x"], packed["y"], packed["z"]], axis=1).astype(np.float64)
    colours = np.stack([(packed["rgb"] >> shift) & 0xFF for shift in (16, 8, 0)], axis=1).astype(np.uint8)
    return points, colours
