"""compressed_to_rgb: image_transport format strings, png/jpeg/tiff via OpenCV, alpha and 16 bit, bad data."""
import array

import cv2
import numpy as np
import pytest
from sensor_msgs.msg import CompressedImage

from msg_adapters import AdapterError, compressed_to_rgb
from msg_adapters.compressed import compression_codec

RNG = np.random.default_rng(3)
BGR = RNG.integers(0, 256, (6, 7, 3), dtype=np.uint8)


def compressed(pixels: np.ndarray, extension: str, format_string: str) -> CompressedImage:
    ok, encoded = cv2.imencode(extension, pixels)
    assert ok
    return CompressedImage(format=format_string, data=array.array("B", encoded.tobytes()))


def smooth_bgr() -> np.ndarray:
    """A smooth gradient, which jpeg keeps to within a few grey levels."""
    y, x = np.mgrid[0:32, 0:48]
    return np.stack([4 * y, 5 * x, 255 - 4 * y], axis=-1).astype(np.uint8)


@pytest.mark.parametrize("format_string", ["rgb8; png compressed bgr8", "bgr8; png compressed bgr8", "png", "PNG", ""])
def test_png_colour_is_exact_in_rgb_order(format_string):
    rgb, alpha = compressed_to_rgb(compressed(BGR, ".png", format_string))
    assert alpha is None and np.array_equal(rgb, BGR[..., ::-1])


def test_png_with_alpha_keeps_it():
    bgra = RNG.integers(0, 256, (5, 4, 4), dtype=np.uint8)
    rgb, alpha = compressed_to_rgb(compressed(bgra, ".png", "bgra8; png compressed bgra8"))
    assert np.array_equal(rgb, bgra[..., 2::-1]) and np.array_equal(alpha, bgra[..., 3])


def test_16_bit_mono_png_is_scaled_to_8_bit():
    grey = np.array([[0, 257, 32896, 65535]], np.uint16)
    rgb, _ = compressed_to_rgb(compressed(grey, ".png", "mono16; png compressed mono16"))
    assert rgb[..., 0].tolist() == [[0, 1, 128, 255]] and (rgb[..., 0] == rgb[..., 2]).all()


@pytest.mark.parametrize("format_string", ["rgb8; jpeg compressed bgr8", "jpeg", "jpg", ""])
def test_jpeg_decodes_close_to_the_original_in_rgb_order(format_string):
    bgr = smooth_bgr()
    rgb, alpha = compressed_to_rgb(compressed(bgr, ".jpg", format_string))
    assert alpha is None and rgb.shape == bgr.shape
    assert np.abs(rgb.astype(int) - bgr[..., ::-1]).mean() < 3


def test_pure_red_stays_red_through_jpeg():
    red_bgr = np.zeros((16, 16, 3), np.uint8)
    red_bgr[..., 2] = 255
    rgb, _ = compressed_to_rgb(compressed(red_bgr, ".jpg", "rgb8; jpeg compressed bgr8"))
    assert rgb[8, 8, 0] > 240 and rgb[8, 8, 1] < 15 and rgb[8, 8, 2] < 15


def test_grey_jpeg_gives_grey_rgb():
    grey = smooth_bgr()[..., 1]
    rgb, _ = compressed_to_rgb(compressed(grey, ".jpg", "mono8; jpeg compressed mono8"))
    assert (rgb[..., 0] == rgb[..., 1]).all() and (rgb[..., 1] == rgb[..., 2]).all()


def test_tiff_is_decoded_losslessly():
    rgb, _ = compressed_to_rgb(compressed(BGR, ".tiff", "bgr8; tiff compressed bgr8"))
    assert np.array_equal(rgb, BGR[..., ::-1])


@pytest.mark.parametrize("format_string, codec", [
    ("rgb8; jpeg compressed bgr8", "jpeg"), ("bgra8; png compressed bgra8", "png"),
    ("mono16; png compressed mono16", "png"), (" jpeg ", "jpeg"), ("tif", "tiff"), ("", None),
])
def test_format_strings_name_the_codec(format_string, codec):
    assert compression_codec(format_string) == codec


def truncated(msg: CompressedImage) -> CompressedImage:
    msg.data = msg.data[: len(msg.data) // 2]
    return msg


@pytest.mark.parametrize("msg, pattern", [
    (CompressedImage(format="jpeg", data=array.array("B", b"not an image at all")), r"does not decode as jpeg"),
    (truncated(compressed(smooth_bgr(), ".jpg", "jpeg")),
     r"CompressedImage.data \(\d+ bytes\) does not decode as jpeg"),
    (CompressedImage(format="png", data=array.array("B", b"\x89PNG\r\n\x1a\n" + bytes(40))), r"does not decode as png"),
    (CompressedImage(format="", data=array.array("B", b"garbage")), r"does not decode as an image"),
    (CompressedImage(format="png", data=array.array("B")), r"CompressedImage.data is empty"),
    (CompressedImage(format="h264", data=array.array("B", b"x")), r"format='h264' names no single jpeg, png or tiff"),
    (CompressedImage(format="jpeg png", data=array.array("B", b"x")), r"names no single"),
    (CompressedImage(format="16UC1; compressedDepth png", data=array.array("B", b"x")), r"compressedDepth transport"),
], ids=["garbage-jpeg", "truncated-jpeg", "truncated-png", "garbage-unnamed", "empty", "h264", "two-codecs",
        "compressed-depth"])
def test_bad_compressed_image_raises_adapter_error(msg, pattern):
    with pytest.raises(AdapterError, match=pattern):
        compressed_to_rgb(msg)
