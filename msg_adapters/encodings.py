"""ROS image encodings (sensor_msgs/image_encodings) as numpy element types, channel counts and layouts."""
import re
from dataclasses import dataclass

import numpy as np

from msg_adapters.errors import AdapterError


@dataclass(frozen=True)
class Encoding:
    """One image encoding: element type (native byte order), channels per pixel and colour layout.

    `layout` says how the channels map to colour: "gray", "rgb", "rgba", "bgr", "bgra",
    "bayer_rggb" / "bayer_bggr" / "bayer_gbrg" / "bayer_grbg" (one channel, a colour mosaic),
    "uyvy" / "yuyv" (packed YUV 4:2:2, two channels) or "none" (no colour meaning).
    """

    name: str
    dtype: np.dtype
    channels: int
    layout: str

    @property
    def pixel_bytes(self) -> int:
        """Bytes per pixel, all channels."""
        return self.dtype.itemsize * self.channels

    @property
    def pixels_per_chroma_pair(self) -> int:
        """Packed YUV 4:2:2 shares one U/V pair between two pixels, so its width must be even."""
        return 2 if self.layout in ("uyvy", "yuyv") else 1


def _named() -> dict[str, Encoding]:
    """The named encodings: mono, colour orders, bayer mosaics and packed YUV."""
    table = {}
    for bits, dtype in ((8, np.dtype(np.uint8)), (16, np.dtype(np.uint16))):
        table[f"mono{bits}"] = Encoding(f"mono{bits}", dtype, 1, "gray")
        for layout in ("rgb", "bgr", "rgba", "bgra"):
            table[f"{layout}{bits}"] = Encoding(f"{layout}{bits}", dtype, len(layout), layout)
        for pattern in ("rggb", "bggr", "gbrg", "grbg"):
            name = f"bayer_{pattern}{bits}"
            table[name] = Encoding(name, dtype, 1, f"bayer_{pattern}")
    table["yuv422"] = Encoding("yuv422", np.dtype(np.uint8), 2, "uyvy")
    table["yuv422_yuy2"] = Encoding("yuv422_yuy2", np.dtype(np.uint8), 2, "yuyv")
    return table


NAMED_ENCODINGS = _named()
_GENERIC = re.compile(r"^(8U|8S|16U|16S|32S|32F|64F)C([1-4])$")
_GENERIC_DTYPES = {
    "8U": np.uint8, "8S": np.int8, "16U": np.uint16, "16S": np.int16,
    "32S": np.int32, "32F": np.float32, "64F": np.float64,
}
# OpenCV's defaults for unnamed matrices, as cv_bridge writes them: 3 channels BGR, 4 channels BGRA.
_GENERIC_LAYOUTS = {1: "gray", 2: "none", 3: "bgr", 4: "bgra"}


def lookup_encoding(name: str) -> Encoding:
    """The Encoding called `name` (exact ROS spelling, e.g. "rgb8", "16UC1"), or AdapterError."""
    if name in NAMED_ENCODINGS:
        return NAMED_ENCODINGS[name]
    match = _GENERIC.match(name)
    if match is None:
        raise AdapterError(
            f"encoding {name!r} is not supported; expected one of {sorted(NAMED_ENCODINGS)} "
            "or a generic <8U|8S|16U|16S|32S|32F|64F>C<1-4> such as '8UC3' or '32FC1'"
        )
    channels = int(match.group(2))
    return Encoding(name, np.dtype(_GENERIC_DTYPES[match.group(1)]), channels, _GENERIC_LAYOUTS[channels])


def check_size(encoding: Encoding, height: int, width: int, owner: str) -> None:
    """AdapterError unless `height` x `width` is a non-empty size the encoding can hold."""
    if height <= 0 or width <= 0:
        raise AdapterError(f"{owner}.height and {owner}.width must be positive, got {height} x {width}")
    if width % encoding.pixels_per_chroma_pair:
        raise AdapterError(
            f"{owner}.width={width} must be even for {encoding.name!r} (two pixels share one U/V pair)"
        )
