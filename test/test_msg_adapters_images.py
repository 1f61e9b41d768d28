"""sensor_msgs/Image <-> numpy: round trips over encodings, sizes, row padding and byte order; bad input."""
import array

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import Image
from std_msgs.msg import Header

from msg_adapters import AdapterError, array_to_image, image_to_array
from msg_adapters.encodings import NAMED_ENCODINGS, lookup_encoding

GENERIC = [f"{depth}C{channels}" for depth in ("8U", "8S", "16U", "16S", "32S", "32F", "64F")
           for channels in (1, 2, 3, 4)]
ALL_ENCODINGS = sorted(NAMED_ENCODINGS) + GENERIC


def wire_image(pixels: np.ndarray, encoding: str, padding: int = 0, big_endian: bool = False) -> Image:
    """An Image built by hand as a driver would send it: rows of `padding` junk bytes, chosen byte order."""
    height, width = pixels.shape[:2]
    wire = pixels.astype(pixels.dtype.newbyteorder(">" if big_endian else "<"))
    rows = np.ascontiguousarray(wire).reshape(height, -1).view(np.uint8)
    padded = np.concatenate([rows, np.full((height, padding), 0xAB, np.uint8)], axis=1)
    return Image(height=height, width=width, encoding=encoding, is_bigendian=int(big_endian),
                 step=padded.shape[1], data=array.array("B", padded.tobytes()))


@st.composite
def pixel_arrays(draw):
    """(encoding, pixels) for any supported encoding, 1-9 rows, 1-9 pixels (even for packed YUV)."""
    name = draw(st.sampled_from(ALL_ENCODINGS))
    spec = lookup_encoding(name)
    height = draw(st.integers(1, 9))
    width = draw(st.integers(1, 9)) * spec.pixels_per_chroma_pair
    shape = (height, width) if spec.channels == 1 else (height, width, spec.channels)
    return name, draw(arrays(spec.dtype, shape))


@settings(max_examples=300, deadline=None)
@given(case=pixel_arrays(), padding_elements=st.integers(0, 5), big_endian=st.booleans())
def test_padded_either_endian_image_reads_back_bit_exact(case, padding_elements, big_endian):
    name, pixels = case
    msg = wire_image(pixels, name, padding_elements * pixels.dtype.itemsize, big_endian)
    result = image_to_array(msg)
    assert result.dtype == pixels.dtype and result.dtype.isnative
    assert result.shape == pixels.shape
    assert result.tobytes() == pixels.tobytes()  # bitwise, so NaN payloads count too


@settings(max_examples=200, deadline=None)
@given(case=pixel_arrays())
def test_array_to_image_writes_tight_rows_that_read_back(case):
    name, pixels = case
    msg = array_to_image(pixels, name)
    spec = lookup_encoding(name)
    assert (msg.height, msg.width, msg.encoding) == (pixels.shape[0], pixels.shape[1], name)
    assert msg.step == pixels.shape[1] * spec.channels * spec.dtype.itemsize
    assert len(msg.data) == msg.step * msg.height
    assert image_to_array(msg).tobytes() == pixels.tobytes()


def test_array_to_image_matches_a_hand_built_wire_image_and_keeps_the_header():
    pixels = np.arange(2 * 3 * 3, dtype=np.uint16).reshape(2, 3, 3) * 1000
    header = Header(frame_id="camera_optical")
    msg = array_to_image(pixels, "rgb16", header)
    assert bytes(msg.data) == bytes(wire_image(pixels, "rgb16").data)
    assert msg.is_bigendian == 0 and msg.header.frame_id == "camera_optical"


def test_single_channel_accepts_a_trailing_channel_axis():
    pixels = np.arange(12, dtype=np.float32).reshape(3, 4, 1)
    assert np.array_equal(image_to_array(array_to_image(pixels, "32FC1")), pixels[..., 0])


def test_received_message_is_copied_not_shared():
    """A message as rclpy delivers it (deserialized): the array must survive changes to msg.data."""
    pixels = np.arange(4 * 5, dtype=np.uint16).reshape(4, 5) * 999
    received = deserialize_message(serialize_message(wire_image(pixels, "mono16", 6, big_endian=True)), Image)
    result = image_to_array(received)
    assert not np.shares_memory(result, np.frombuffer(received.data, np.uint8))
    assert result.flags.writeable and result.flags.c_contiguous
    received.data[:] = array.array("B", bytes(len(received.data)))
    assert np.array_equal(result, pixels)


def good_mono16() -> Image:
    return wire_image(np.ones((3, 4), np.uint16), "mono16", padding=2)


def with_fields(msg: Image, **fields) -> Image:
    for name, value in fields.items():
        setattr(msg, name, value)
    return msg


@pytest.mark.parametrize("msg, pattern", [
    (with_fields(good_mono16(), encoding="rgb9"), r"encoding 'rgb9' is not supported"),
    (with_fields(good_mono16(), encoding=""), r"encoding '' is not supported"),
    (with_fields(good_mono16(), encoding="8UC5"), r"encoding '8UC5' is not supported"),
    (with_fields(good_mono16(), height=0, data=array.array("B")), r"Image.height and Image.width must be positive"),
    (with_fields(good_mono16(), width=0), r"Image.height and Image.width must be positive"),
    (with_fields(good_mono16(), data=good_mono16().data[:-1]),
     r"Image.data has 29 bytes; expected step\*height = 10\*3 = 30"),
    (with_fields(good_mono16(), data=good_mono16().data * 2), r"Image.data has 60 bytes; expected"),
    (with_fields(good_mono16(), data=array.array("B")), r"Image.data has 0 bytes"),
    (with_fields(good_mono16(), step=7), r"Image.step=7 is smaller than width\*channels\*bytes = 4\*1\*2 = 8"),
    (with_fields(good_mono16(), step=9, data=array.array("B", bytes(27))),
     r"Image.step=9 is not a multiple of the 2-byte"),
    (with_fields(wire_image(np.zeros((2, 4, 2), np.uint8), "yuv422"), width=3, step=6), r"Image.width=3 must be even"),
], ids=lambda value: value if isinstance(value, str) else "")
def test_bad_image_raises_adapter_error_naming_the_field(msg, pattern):
    with pytest.raises(AdapterError, match=pattern):
        image_to_array(msg)


@pytest.mark.parametrize("pixels, encoding, pattern", [
    (np.zeros((2, 2, 3), np.uint8), "rgb9", r"encoding 'rgb9' is not supported"),
    (np.zeros((2, 2, 3), np.float32), "rgb8", r"array dtype float32 does not match encoding 'rgb8'; expected uint8"),
    (np.zeros((2, 2), np.uint16), "mono8", r"array dtype uint16 does not match"),
    (np.zeros((2, 2), np.uint8), "rgb8", r"array shape \(2, 2\) does not fit encoding 'rgb8'; expected \(H, W, 3\)"),
    (np.zeros((2, 2, 4), np.uint8), "bgr8", r"expected \(H, W, 3\)"),
    (np.zeros((2, 2, 2), np.uint8), "mono8", r"expected \(H, W\)"),
    (np.zeros(4, np.uint8), "mono8", r"array shape \(4,\)"),
    (np.zeros((0, 3), np.uint8), "mono8", r"array.height and array.width must be positive"),
    (np.zeros((2, 3, 2), np.uint8), "yuv422", r"array.width=3 must be even"),
    (np.array([["a"]]), "mono8", r"array dtype <U1 does not match"),
])
def test_bad_array_raises_adapter_error(pixels, encoding, pattern):
    with pytest.raises(AdapterError, match=pattern):
        array_to_image(pixels, encoding)


def test_adapter_error_is_a_value_error():
    assert issubclass(AdapterError, ValueError)
