"""sensor_msgs/Image <-> numpy arrays, honouring row padding (`step`) and byte order (`is_bigendian`)."""
import array

import numpy as np
from sensor_msgs.msg import Image
from std_msgs.msg import Header

from msg_adapters.encodings import Encoding, check_size, lookup_encoding
from msg_adapters.errors import AdapterError
from msg_adapters.image_size import check_pixels
from msg_adapters.rgb import pixels_to_rgb


def checked_layout(msg: Image, max_pixels: int | None = None) -> tuple[Encoding, int, int, int]:
    """(encoding, height, width, step) of ``msg`` once its encoding, size, row padding and data length agree;
    AdapterError names what does not (``ImageTooLarge`` above ``max_pixels``). Reads no pixel."""
    encoding = lookup_encoding(msg.encoding)
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    check_size(encoding, height, width, "Image")
    check_pixels(width, height, max_pixels, "Image")
    row_bytes = width * encoding.pixel_bytes
    if step < row_bytes:
        raise AdapterError(
            f"Image.step={step} is smaller than width*channels*bytes = {width}*{encoding.channels}*"
            f"{encoding.dtype.itemsize} = {row_bytes} for encoding {encoding.name!r}"
        )
    if step % encoding.dtype.itemsize:
        raise AdapterError(
            f"Image.step={step} is not a multiple of the {encoding.dtype.itemsize}-byte element "
            f"of encoding {encoding.name!r}"
        )
    if len(msg.data) != step * height:
        raise AdapterError(
            f"Image.data has {len(msg.data)} bytes; expected step*height = {step}*{height} = {step * height}"
        )
    return encoding, height, width, step


def image_to_array(msg: Image, max_pixels: int | None = None) -> np.ndarray:
    """The pixels of `msg` as a fresh (H, W) or (H, W, C) array of the encoding's dtype, native byte order.

    Always a copy: rclpy may reuse the message buffer after the callback returns. More than
    ``max_pixels`` pixels raise ``ImageTooLarge`` before ``data`` is touched.
    """
    encoding, height, width, step = checked_layout(msg, max_pixels)
    row_bytes = width * encoding.pixel_bytes
    data = np.frombuffer(msg.data, dtype=np.uint8)
    wire_dtype = encoding.dtype.newbyteorder(">" if msg.is_bigendian else "<")
    rows = data.reshape(height, step)[:, :row_bytes].view(wire_dtype)
    shape = (height, width) if encoding.channels == 1 else (height, width, encoding.channels)
    return rows.reshape(shape).astype(encoding.dtype, copy=True)


def array_to_image(arr: np.ndarray, encoding: str, header: Header | None = None) -> Image:
    """A little-endian Image with tight rows from an (H, W) or (H, W, C) array of the encoding's dtype."""
    spec = lookup_encoding(encoding)
    pixels = np.asarray(arr)
    if (pixels.dtype.kind, pixels.dtype.itemsize) != (spec.dtype.kind, spec.dtype.itemsize):
        raise AdapterError(f"array dtype {pixels.dtype} does not match encoding {encoding!r}; expected {spec.dtype}")
    if spec.channels == 1 and pixels.ndim == 3 and pixels.shape[2] == 1:
        pixels = pixels[..., 0]
    channel_shape = () if spec.channels == 1 else (spec.channels,)
    if pixels.ndim < 2 or pixels.shape[2:] != channel_shape:
        expected = "(H, W)" if spec.channels == 1 else f"(H, W, {spec.channels})"
        raise AdapterError(f"array shape {pixels.shape} does not fit encoding {encoding!r}; expected {expected}")
    height, width = pixels.shape[:2]
    check_size(spec, height, width, "array")
    little_endian = np.ascontiguousarray(pixels, dtype=spec.dtype.newbyteorder("<"))
    data = array.array("B")
    data.frombytes(little_endian.reshape(-1).view(np.uint8))  # one copy, no Python-level iteration
    return Image(
        header=header if header is not None else Header(),
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=0,
        step=width * spec.pixel_bytes,
        data=data,
    )


def image_to_rgb(msg: Image, max_pixels: int | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """(RGB uint8 (H, W, 3), alpha uint8 (H, W) or None) from any supported encoding.

    Bayer and YUV are converted by OpenCV; 16-bit values scale by 255/65535, floats from [0, 1].
    More than ``max_pixels`` pixels raise ``ImageTooLarge`` before anything is read.
    """
    encoding = lookup_encoding(msg.encoding)
    return pixels_to_rgb(image_to_array(msg, max_pixels), encoding.layout, f"Image encoding {encoding.name!r}")
