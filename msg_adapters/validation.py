"""Is an image message well formed? Checked from its fields and header bytes, without decoding a pixel.

A bag reader uses it to list the views it can use without decoding every image on the topic; the
pixels are decoded once, later, for the views an evaluation actually estimates.
"""
from sensor_msgs.msg import CompressedImage, Image

from msg_adapters.compressed import compression_codec
from msg_adapters.errors import AdapterError
from msg_adapters.image_size import encoded_size
from msg_adapters.images import checked_layout


def check_image(message: Image | CompressedImage) -> tuple[int, int]:
    """(width, height) of a well-formed Image or CompressedImage; AdapterError names what is wrong with it."""
    if isinstance(message, Image):
        _, height, width, _ = checked_layout(message)
        return width, height
    compression_codec(message.format)
    if not len(message.data):
        raise AdapterError("CompressedImage.data is empty; expected an encoded jpeg/png/tiff image")
    return encoded_size(bytes(message.data))
