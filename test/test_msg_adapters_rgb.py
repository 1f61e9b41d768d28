"""image_to_rgb: colour orders against OpenCV's cvtColor, Bayer patterns against a known colour, 8-bit scaling."""
import cv2
import numpy as np
import pytest

from msg_adapters import AdapterError, array_to_image, image_to_rgb

RNG = np.random.default_rng(7)
BGR = RNG.integers(0, 256, (5, 6, 3), dtype=np.uint8)
BGRA = RNG.integers(0, 256, (5, 6, 4), dtype=np.uint8)
GREY = RNG.integers(0, 256, (5, 6), dtype=np.uint8)


@pytest.mark.parametrize("encoding, pixels, expected_rgb, expected_alpha", [
    ("rgb8", BGR, BGR, None),
    ("bgr8", BGR, cv2.cvtColor(BGR, cv2.COLOR_BGR2RGB), None),
    ("8UC3", BGR, cv2.cvtColor(BGR, cv2.COLOR_BGR2RGB), None),
    ("rgba8", BGRA, BGRA[..., :3], BGRA[..., 3]),
    ("bgra8", BGRA, cv2.cvtColor(BGRA, cv2.COLOR_BGRA2RGB), BGRA[..., 3]),
    ("8UC4", BGRA, cv2.cvtColor(BGRA, cv2.COLOR_BGRA2RGB), BGRA[..., 3]),
    ("mono8", GREY, cv2.cvtColor(GREY, cv2.COLOR_GRAY2RGB), None),
    ("8UC1", GREY, cv2.cvtColor(GREY, cv2.COLOR_GRAY2RGB), None),
])
def test_colour_orders_match_opencv(encoding, pixels, expected_rgb, expected_alpha):
    rgb, alpha = image_to_rgb(array_to_image(pixels, encoding))
    assert rgb.dtype == np.uint8 and rgb.shape == (5, 6, 3)
    assert np.array_equal(rgb, expected_rgb)
    assert (alpha is None) if expected_alpha is None else np.array_equal(alpha, expected_alpha)


def test_16_bit_colour_matches_opencv_order_and_scale():
    """bgr16 -> cvtColor order; 65535 -> 255, scaled by 255/65535 and rounded."""
    pixels = RNG.integers(0, 65536, (4, 4, 3), dtype=np.uint16)
    rgb, _ = image_to_rgb(array_to_image(pixels, "bgr16"))
    expected = np.rint(cv2.cvtColor(pixels, cv2.COLOR_BGR2RGB) * (255 / 65535)).astype(np.uint8)
    assert np.array_equal(rgb, expected)


def test_mono16_scales_full_range_to_8_bit():
    values = np.array([[0, 128, 129, 257, 32896, 65535]], np.uint16)
    rgb, alpha = image_to_rgb(array_to_image(values, "mono16"))
    expected = np.rint(values * (255 / 65535)).astype(np.uint8)
    assert alpha is None and np.array_equal(rgb[..., 0], expected) and np.array_equal(rgb[..., 2], expected)
    assert expected.tolist() == [[0, 0, 1, 1, 128, 255]]


@pytest.mark.parametrize("encoding, dtype", [("32FC1", np.float32), ("64FC1", np.float64)])
def test_float_mono_maps_unit_range_to_8_bit_clipping_and_zeroing_nan(encoding, dtype):
    values = np.array([[-1.0, 0.0, 0.25, 0.5, 1.0, 2.0, np.nan, np.inf, -np.inf]], dtype)
    rgb, _ = image_to_rgb(array_to_image(values, encoding))
    assert rgb[0, :, 1].tolist() == [0, 0, 64, 128, 255, 255, 0, 255, 0]


def test_float_colour_with_alpha():
    pixels = np.array([[[0.0, 0.5, 1.0, 0.25]]], np.float32)  # B, G, R, A
    rgb, alpha = image_to_rgb(array_to_image(pixels, "32FC4"))
    assert rgb.tolist() == [[[255, 128, 0]]] and alpha.tolist() == [[64]]


def bayer_mosaic(pattern: str, rgb: tuple[int, int, int], size: int, dtype) -> np.ndarray:
    """A size x size mosaic of one flat colour: each pixel keeps the channel its 2x2 pattern cell names."""
    channel = {"r": 0, "g": 1, "b": 2}
    cells = np.array([[channel[pattern[0]], channel[pattern[1]]], [channel[pattern[2]], channel[pattern[3]]]])
    which = np.tile(cells, (size // 2, size // 2))
    return np.asarray(rgb, dtype)[which]


@pytest.mark.parametrize("pattern", ["rggb", "bggr", "gbrg", "grbg"])
@pytest.mark.parametrize("bits, dtype, unit", [(8, np.uint8, 1), (16, np.uint16, 257)])
def test_bayer_patterns_demosaic_a_flat_colour_exactly(pattern, bits, dtype, unit):
    colour = (200, 100, 30)
    mosaic = bayer_mosaic(pattern, tuple(c * unit for c in colour), 8, dtype)
    rgb, alpha = image_to_rgb(array_to_image(mosaic, f"bayer_{pattern}{bits}"))
    assert alpha is None and rgb.shape == (8, 8, 3)
    assert (rgb[2:-2, 2:-2] == colour).all(), f"interior colour {rgb[4, 4].tolist()}, expected {colour}"


@pytest.mark.parametrize("pattern", ["rggb", "bggr", "gbrg", "grbg"])
def test_bayer_matches_opencv_demosaic_of_a_random_mosaic(pattern):
    mosaic = RNG.integers(0, 256, (6, 8), dtype=np.uint8)
    rgb, _ = image_to_rgb(array_to_image(mosaic, f"bayer_{pattern}8"))
    code = getattr(cv2, f"COLOR_Bayer{pattern.upper()}2RGB")
    assert np.array_equal(rgb, cv2.cvtColor(mosaic, code))


def test_packed_yuv_orders_decode_the_same_picture():
    """UYVY (yuv422) and YUYV (yuv422_yuy2) with the same samples give OpenCV's RGB for both."""
    yuyv = RNG.integers(16, 240, (3, 4, 2), dtype=np.uint8)
    as_bytes = yuyv.reshape(3, 2, 4)  # per pixel pair: Y0 U Y1 V
    uyvy = as_bytes[..., [1, 0, 3, 2]].reshape(3, 4, 2)  # U Y0 V Y1
    rgb_uyvy, _ = image_to_rgb(array_to_image(uyvy, "yuv422"))
    rgb_yuyv, _ = image_to_rgb(array_to_image(yuyv, "yuv422_yuy2"))
    assert np.array_equal(rgb_uyvy, cv2.cvtColor(uyvy, cv2.COLOR_YUV2RGB_UYVY))
    assert np.array_equal(rgb_uyvy, rgb_yuyv)


@pytest.mark.parametrize("encoding, dtype, channels, pattern", [
    ("16SC1", np.int16, 1, r"signed int16 pixels"),
    ("32SC1", np.int32, 1, r"signed int32 pixels"),
    ("8SC3", np.int8, 3, r"signed int8 pixels"),
    ("8UC2", np.uint8, 2, r"'8UC2' has no colour meaning"),
])
def test_encodings_without_a_display_meaning_raise(encoding, dtype, channels, pattern):
    shape = (2, 2) if channels == 1 else (2, 2, channels)
    with pytest.raises(AdapterError, match=pattern):
        image_to_rgb(array_to_image(np.zeros(shape, dtype), encoding))
