"""Pixels in any layout and depth -> 8-bit RGB plus alpha, with OpenCV doing the colour conversions."""
import cv2
import numpy as np

from msg_adapters.errors import AdapterError

# OpenCV conversion from each layout to RGB (or RGBA where there is alpha); None: already in order.
_TO_RGB = {
    "gray": cv2.COLOR_GRAY2RGB,
    "rgb": None,
    "rgba": None,
    "bgr": cv2.COLOR_BGR2RGB,
    "bgra": cv2.COLOR_BGRA2RGBA,
    # OpenCV's four-letter Bayer names read the pattern from the top-left pixel, as ROS does.
    "bayer_rggb": cv2.COLOR_BayerRGGB2RGB,
    "bayer_bggr": cv2.COLOR_BayerBGGR2RGB,
    "bayer_gbrg": cv2.COLOR_BayerGBRG2RGB,
    "bayer_grbg": cv2.COLOR_BayerGRBG2RGB,
    "uyvy": cv2.COLOR_YUV2RGB_UYVY,
    "yuyv": cv2.COLOR_YUV2RGB_YUY2,
}


def to_uint8(pixels: np.ndarray) -> np.ndarray:
    """Scale to uint8: 16-bit by 255/65535 (rounded), float from [0, 1] (clipped, NaN -> 0)."""
    if pixels.dtype == np.uint8:
        return pixels
    if pixels.dtype == np.uint16:
        return ((pixels.astype(np.uint32) + 128) // 257).astype(np.uint8)
    unit = np.clip(np.nan_to_num(pixels, nan=0.0), 0.0, 1.0)
    return np.rint(unit * 255.0).astype(np.uint8)


def pixels_to_rgb(pixels: np.ndarray, layout: str, source: str) -> tuple[np.ndarray, np.ndarray | None]:
    """(H, W[, C]) pixels in `layout` -> (RGB uint8 (H, W, 3), alpha uint8 (H, W) or None).

    Colour is converted before scaling so Bayer mosaics are demosaiced at full depth.
    `source` names the input in error messages (e.g. "Image encoding '16SC1'").
    """
    if layout not in _TO_RGB:
        raise AdapterError(f"{source} has no colour meaning; expected grey, RGB(A), BGR(A), Bayer or YUV")
    if pixels.dtype.kind not in "uf":
        raise AdapterError(f"{source} has signed {pixels.dtype} pixels with no display scale; "
                           "expected unsigned integer or float pixels")
    if pixels.dtype == np.float64:
        pixels = pixels.astype(np.float32)  # OpenCV converts colour at 8U, 16U and 32F only
    code = _TO_RGB[layout]
    try:
        colour = pixels if code is None else cv2.cvtColor(pixels, code)
    except cv2.error as error:
        raise AdapterError(f"{source}: OpenCV cannot convert {layout} pixels of shape {pixels.shape} "
                           f"and type {pixels.dtype} to RGB: {error}") from error
    colour = to_uint8(colour)
    if colour.shape[2] == 4:
        return np.ascontiguousarray(colour[..., :3]), np.ascontiguousarray(colour[..., 3])
    return np.ascontiguousarray(colour), None
