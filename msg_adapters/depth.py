"""Depth and mask images <-> numpy: sensor_msgs/Image `16UC1` (millimetres) / `32FC1` (metres), `mono8` masks."""
import numpy as np
from sensor_msgs.msg import Image
from std_msgs.msg import Header

from msg_adapters.errors import AdapterError
from msg_adapters.images import array_to_image, image_to_array

MILLIMETRE = 0.001
DEPTH_ENCODINGS = ("16UC1", "mono16", "32FC1")  # mono16 is how some drivers label millimetre depth


def image_to_depth(msg: Image) -> np.ndarray:
    """Depth in metres (H, W) float32 from `16UC1`/`mono16` millimetres (the RealSense convention) or `32FC1`
    metres; no reading (0, NaN, inf) becomes 0."""
    if msg.encoding not in DEPTH_ENCODINGS:
        raise AdapterError(f"Image.encoding {msg.encoding!r} is not a depth encoding; expected one of "
                           f"{', '.join(DEPTH_ENCODINGS)}")
    pixels = image_to_array(msg)
    metres = pixels.astype(np.float32) * (MILLIMETRE if pixels.dtype == np.uint16 else 1.0)
    return np.where(np.isfinite(metres) & (metres > 0), metres, np.float32(0.0))


def depth_to_image(depth: np.ndarray, encoding: str = "16UC1", header: Header | None = None) -> Image:
    """Depth in metres (H, W) -> an Image in `16UC1` (rounded millimetres, 0 = no reading) or `32FC1`."""
    depth = np.asarray(depth, dtype=np.float64)
    if encoding == "16UC1":
        millimetres = np.where(np.isfinite(depth), np.round(depth / MILLIMETRE), 0.0)
        return array_to_image(np.clip(millimetres, 0, 65535).astype(np.uint16), encoding, header)
    if encoding == "32FC1":
        return array_to_image(depth.astype(np.float32), encoding, header)
    raise AdapterError(f"depth images are written as 16UC1 or 32FC1, not {encoding!r}")


def image_to_mask(msg: Image) -> np.ndarray:
    """An object mask (H, W) bool from a `mono8`/`8UC1` image (non-zero = object), as segmentation nodes publish."""
    if msg.encoding not in ("mono8", "8UC1"):
        raise AdapterError(f"a mask Image must be mono8 or 8UC1, got {msg.encoding!r}")
    return image_to_array(msg) > 0
