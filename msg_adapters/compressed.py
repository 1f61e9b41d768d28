"""sensor_msgs/CompressedImage (jpeg, png, tiff as image_transport writes them) -> 8-bit RGB and alpha."""
import re

import cv2
import numpy as np
from sensor_msgs.msg import CompressedImage

from msg_adapters.errors import AdapterError
from msg_adapters.image_size import check_pixels, encoded_size
from msg_adapters.rgb import pixels_to_rgb

_CODECS = {"jpeg": "jpeg", "jpg": "jpeg", "png": "png", "tiff": "tiff", "tif": "tiff"}
# OpenCV's decoded channel order by channel count; jpeg always decodes to 3-channel BGR.
_DECODED_LAYOUTS = {1: "gray", 3: "bgr", 4: "bgra"}


def compression_codec(format_string: str) -> str | None:
    """"jpeg", "png" or "tiff" from a format such as "rgb8; jpeg compressed bgr8"; None when empty (sniff)."""
    tokens = [token for token in re.split(r"[;\s]+", format_string.strip().lower()) if token]
    if any(token.startswith("compresseddepth") for token in tokens):
        raise AdapterError(
            f"CompressedImage.format={format_string!r} is the compressedDepth transport (quantised depth); "
            "expected a colour or grey jpeg/png/tiff image"
        )
    if not tokens:
        return None
    codecs = {_CODECS[token] for token in tokens if token in _CODECS}
    if len(codecs) != 1:
        raise AdapterError(
            f"CompressedImage.format={format_string!r} names no single jpeg, png or tiff codec; expected e.g. "
            "'rgb8; jpeg compressed bgr8', 'bgra8; png compressed bgra8', 'jpeg' or 'png'"
        )
    return codecs.pop()


def compressed_to_rgb(msg: CompressedImage, max_pixels: int | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """(RGB uint8 (H, W, 3), alpha uint8 (H, W) or None) decoded by OpenCV.

    png and tiff keep alpha and 16-bit depth (scaled by 255/65535); an empty format is sniffed.
    With ``max_pixels``, the size is read from the png/jpeg/tiff header first and a larger image
    raises ``ImageTooLarge`` before anything is decoded.
    """
    codec = compression_codec(msg.format)
    data = np.frombuffer(msg.data, dtype=np.uint8)
    if data.size == 0:
        raise AdapterError("CompressedImage.data is empty; expected an encoded jpeg/png/tiff image")
    if max_pixels is not None:
        check_pixels(*encoded_size(data.tobytes()), max_pixels, "CompressedImage")
    flags = cv2.IMREAD_COLOR if codec == "jpeg" else cv2.IMREAD_UNCHANGED
    try:
        pixels = cv2.imdecode(data, flags)
    except cv2.error:
        pixels = None
    if pixels is None:
        raise AdapterError(
            f"CompressedImage.data ({data.size} bytes) does not decode as {codec or 'an image'} "
            f"(format {msg.format!r})"
        )
    channels = 1 if pixels.ndim == 2 else pixels.shape[2]
    if channels not in _DECODED_LAYOUTS:
        raise AdapterError(f"CompressedImage decoded to {channels} channels; expected 1, 3 or 4")
    return pixels_to_rgb(pixels, _DECODED_LAYOUTS[channels], f"CompressedImage format {msg.format!r}")
