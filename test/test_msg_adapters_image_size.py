"""Image sizes read before decoding (png, jpeg, tiff headers) and the pixel limit of the image adapters."""
import array
import struct

import cv2
import numpy as np
import pytest
from sensor_msgs.msg import CompressedImage, Image

from msg_adapters import AdapterError, ImageTooLarge, compressed_to_rgb, encoded_size, image_to_rgb

LIMIT = 4096 * 4096
RNG = np.random.default_rng(5)


def encoded(extension: str, pixels: np.ndarray, *flags: int) -> bytes:
    ok, data = cv2.imencode(extension, pixels, list(flags))
    assert ok
    return data.tobytes()


@pytest.mark.parametrize("width, height", [(7, 5), (640, 480), (1, 300)])
@pytest.mark.parametrize("extension, channels, dtype, flags", [
    (".png", 3, np.uint8, ()), (".png", 4, np.uint8, ()), (".png", 1, np.uint16, ()),
    (".jpg", 3, np.uint8, ()), (".jpg", 1, np.uint8, ()), (".jpg", 3, np.uint8, (cv2.IMWRITE_JPEG_PROGRESSIVE, 1)),
    (".tiff", 3, np.uint8, ()), (".tiff", 1, np.uint16, ()),
], ids=["png", "png-rgba", "png-16bit", "jpeg", "jpeg-grey", "jpeg-progressive", "tiff", "tiff-16bit"])
def test_the_header_size_is_the_decoded_size(width, height, extension, channels, dtype, flags):
    shape = (height, width) if channels == 1 else (height, width, channels)
    data = encoded(extension, RNG.integers(0, 200, shape).astype(dtype), *flags)
    assert encoded_size(data) == (width, height)
    assert cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED).shape[:2] == (height, width)


def test_jpeg_segments_and_fill_bytes_before_the_frame_header_are_skipped():
    data = encoded(".jpg", RNG.integers(0, 255, (30, 50, 3), dtype=np.uint8))
    exif = b"\xff\xe1" + struct.pack(">H", 2 + 1000) + bytes(1000)  # an APP1 segment as a camera writes it
    assert encoded_size(data[:2] + exif + b"\xff\xff" + data[2:]) == (50, 30)


def test_a_big_endian_tiff_header_is_read():
    entries = [(256, 3, 1, struct.pack(">HH", 321, 0)), (257, 4, 1, struct.pack(">I", 123))]
    ifd = struct.pack(">H", len(entries)) + b"".join(struct.pack(">HHI", tag, kind, count) + value
                                                    for tag, kind, count, value in entries)
    assert encoded_size(b"MM\x00*" + struct.pack(">I", 8) + ifd + bytes(4)) == (321, 123)


def test_a_decompression_bomb_is_refused_before_decoding(png_bomb):
    assert len(png_bomb) < 200_000 and encoded_size(png_bomb) == (12000, 12000)
    msg = CompressedImage(format="png", data=array.array("B", png_bomb))
    with pytest.raises(ImageTooLarge, match=r"CompressedImage is 12000x12000 = 144000000 pixels, more than the "
                                            r"limit of 16777216; refused before decoding"):
        compressed_to_rgb(msg, max_pixels=LIMIT)


def test_a_raw_image_is_refused_on_its_size_before_its_data_is_read():
    msg = Image(height=12000, width=12000, encoding="rgb8", step=36000, data=array.array("B", b"\x00" * 10))
    with pytest.raises(ImageTooLarge, match=r"Image is 12000x12000 = 144000000 pixels"):
        image_to_rgb(msg, max_pixels=LIMIT)
    with pytest.raises(AdapterError, match="Image.data has 10 bytes"):  # without a limit: the data check
        image_to_rgb(msg)


def test_images_within_the_limit_decode_as_before():
    rgb = RNG.integers(0, 255, (48, 64, 3), dtype=np.uint8)
    png = CompressedImage(format="png", data=array.array("B", encoded(".png", rgb[..., ::-1])))
    assert np.array_equal(compressed_to_rgb(png, max_pixels=64 * 48)[0], rgb)
    with pytest.raises(ImageTooLarge):
        compressed_to_rgb(png, max_pixels=64 * 48 - 1)


@pytest.mark.parametrize("data, pattern", [
    (b"GIF89a" + bytes(20), r"is not a png, jpeg or tiff image \(it begins with bytes 47 49 46"),
    (b"\x89PNG\r\n\x1a\n" + bytes(6), "ends inside its image header"),
    (b"\x89PNG\r\n\x1a\n" + bytes(4) + b"IDAT" + bytes(20), "png without an IHDR"),
    (b"\xff\xd8\xff\xdb\x00\x04\x00\x00\xff\xda\x00\x02", "jpeg without a frame header"),
    (b"\xff\xd8\xff\xe0\x00\x10JFIF", "ends inside its image header"),
    (b"II*\x00" + struct.pack("<IH", 8, 0) + bytes(4), "tiff whose first directory gives no width and height"),
], ids=["gif", "short-png", "png-no-ihdr", "jpeg-no-frame", "jpeg-cut", "tiff-no-size"])
def test_headers_that_give_no_size_are_refused_when_a_limit_applies(data, pattern):
    with pytest.raises(AdapterError, match=pattern):
        encoded_size(data)
    with pytest.raises(AdapterError, match=pattern):
        compressed_to_rgb(CompressedImage(format="", data=array.array("B", data)), max_pixels=LIMIT)
