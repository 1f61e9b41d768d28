"""An image's size before it is decoded: from a png, jpeg or tiff header, and a pixel limit to check it against.

A 140 KB png can decode to 12000 x 12000 pixels (430 MB of RGB): the size has to be known, and
refused, before the decoder allocates anything.
"""
import struct

from msg_adapters.errors import AdapterError

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
JPEG_START = b"\xff\xd8"
TIFF_ORDERS = {b"II*\x00": "<", b"MM\x00*": ">"}
# JPEG start-of-frame markers (baseline, progressive, lossless, arithmetic); C4, C8, CC are other tables.
JPEG_FRAMES = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}
JPEG_NO_LENGTH = {0x01, *range(0xD0, 0xD8)}  # TEM and RSTn stand alone
TIFF_WIDTH, TIFF_HEIGHT = 256, 257
TIFF_FORMATS = {3: "H", 4: "I"}  # SHORT, LONG


class ImageTooLarge(AdapterError):
    """An image with more pixels than the caller's limit, refused before decoding."""


def check_pixels(width: int, height: int, max_pixels: int | None, owner: str) -> None:
    """``ImageTooLarge`` when ``width`` x ``height`` exceeds ``max_pixels`` (None: no limit)."""
    if max_pixels is not None and width * height > max_pixels:
        raise ImageTooLarge(f"{owner} is {width}x{height} = {width * height} pixels, more than the limit of "
                            f"{max_pixels}; refused before decoding")


def encoded_size(data: bytes) -> tuple[int, int]:
    """(width, height) from the header of png, jpeg or tiff ``data``; AdapterError if it is none of them."""
    try:
        if data.startswith(PNG_SIGNATURE):
            return _png_size(data)
        if data.startswith(JPEG_START):
            return _jpeg_size(data)
        if data[:4] in TIFF_ORDERS:
            return _tiff_size(data, TIFF_ORDERS[data[:4]])
    except (struct.error, IndexError) as error:
        raise AdapterError(f"CompressedImage.data ends inside its image header ({len(data)} bytes)") from error
    raise AdapterError(f"CompressedImage.data ({len(data)} bytes) is not a png, jpeg or tiff image "
                       f"(it begins with bytes {data[:8].hex(' ')}); its size cannot be checked before decoding")


def _png_size(data: bytes) -> tuple[int, int]:
    """The IHDR chunk comes first: length, b"IHDR", width, height (big-endian)."""
    _, kind, width, height = struct.unpack(">I4sII", data[8:24])
    if kind != b"IHDR":
        raise AdapterError("CompressedImage.data is a png without an IHDR header chunk")
    return width, height


def _jpeg_size(data: bytes) -> tuple[int, int]:
    """Walk the marker segments up to the start-of-frame, which holds height then width."""
    position = 2
    while True:
        position = data.find(b"\xff", position)  # stray bytes between segments are skipped, as decoders do
        if position < 0:
            raise IndexError("no further marker")
        position = len(data) - len(data[position:].lstrip(b"\xff"))  # past the fill bytes
        marker = data[position]
        position += 1
        if marker in JPEG_NO_LENGTH:
            continue
        (length,) = struct.unpack(">H", data[position:position + 2])
        if marker in JPEG_FRAMES:
            height, width = struct.unpack(">HH", data[position + 3:position + 7])
            if height == 0 or width == 0:
                raise AdapterError(f"CompressedImage.data is a jpeg whose frame header gives a size of "
                                   f"{width}x{height}")
            return width, height
        if marker in (0xD9, 0xDA) or length < 2:  # end of image or scan data before any frame header
            raise AdapterError("CompressedImage.data is a jpeg without a frame header")
        position += length


def _tiff_size(data: bytes, order: str) -> tuple[int, int]:
    """ImageWidth (256) and ImageLength (257) of the first image file directory."""
    (offset,) = struct.unpack(order + "I", data[4:8])
    (count,) = struct.unpack(order + "H", data[offset:offset + 2])
    found = {}
    for entry in range(offset + 2, offset + 2 + 12 * count, 12):
        tag, kind = struct.unpack(order + "HH", data[entry:entry + 4])
        if tag in (TIFF_WIDTH, TIFF_HEIGHT) and kind in TIFF_FORMATS:
            found[tag] = struct.unpack(order + TIFF_FORMATS[kind], data[entry + 8:entry + 8 + struct.calcsize(
                TIFF_FORMATS[kind])])[0]
    if len(found) != 2:
        raise AdapterError("CompressedImage.data is a tiff whose first directory gives no width and height")
    return found[TIFF_WIDTH], found[TIFF_HEIGHT]
