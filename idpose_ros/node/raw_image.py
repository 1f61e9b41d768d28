"""An image message as it arrived, decoded only when it becomes a view.

A 30 Hz camera stream must not cost a decode per frame when one frame in many is kept: the node
remembers the latest message and decodes it (size-checked first) at capture.
"""
from __future__ import annotations

from dataclasses import dataclass

from builtin_interfaces.msg import Time
from sensor_msgs.msg import CompressedImage, Image

from idpose_core.pipeline import ViewInput
from idpose_ros.view_decoding import decode_image


@dataclass(frozen=True)
class RawImage:
    """An ``Image`` or ``CompressedImage`` and the topic it came on."""

    message: Image | CompressedImage
    topic: str

    @property
    def frame_id(self) -> str:
        return self.message.header.frame_id

    @property
    def stamp(self) -> Time:
        return self.message.header.stamp

    @property
    def source(self) -> str:
        """E.g. "Image rgb8" or "CompressedImage png", for log lines and answers."""
        if isinstance(self.message, Image):
            return f"Image {self.message.encoding}"
        return f"CompressedImage {self.message.format}"

    def decode(self, max_pixels: int) -> ViewInput:
        """The pixels as the pipeline takes them; ``AdapterError`` (``ImageTooLarge`` above ``max_pixels``,
        checked before decoding) when they cannot be read."""
        return ViewInput(*decode_image(self.message, max_pixels))
