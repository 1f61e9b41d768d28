"""A view's messages -> the pipeline's ``ViewInput``: image, depth, mask and intrinsics decoded by msg_adapters.

The node and the bag evaluator both go through ``view_input``, so a view means the same to both.
"""
from __future__ import annotations

import numpy as np
from sensor_msgs.msg import CameraInfo, CompressedImage, Image

from idpose_core.view_input import ViewInput
from msg_adapters import (
    AdapterError,
    camera_info_intrinsics,
    compressed_to_rgb,
    image_to_depth,
    image_to_mask,
    image_to_rgb,
)


def decode_image(message: Image | CompressedImage) -> tuple[np.ndarray, np.ndarray | None]:
    """(rgb (H, W, 3) uint8, alpha (H, W) uint8 | None) of an Image or CompressedImage."""
    return (image_to_rgb if isinstance(message, Image) else compressed_to_rgb)(message)


def view_input(image: Image | CompressedImage, depth: Image | None = None, mask: Image | None = None,
               camera_info: CameraInfo | None = None, gravity_up: np.ndarray | None = None,
               roi: tuple[int, int, int, int] | None = None) -> ViewInput:
    """Decode one view; AdapterError names the message that does not decode or does not fit the image
    (depth and mask must be aligned to it: the same width and height; so must the CameraInfo)."""
    rgb, alpha = decode_image(image)
    height, width = rgb.shape[:2]
    decoded = {"depth": image_to_depth(depth) if depth is not None else None,
               "mask": image_to_mask(mask) if mask is not None else None}
    for name, array in decoded.items():
        if array is not None and array.shape != (height, width):
            raise AdapterError(f"the {name} image is {array.shape[1]}x{array.shape[0]}, the colour image "
                               f"{width}x{height}: they must be aligned (e.g. aligned_depth_to_color)")
    intrinsics = None
    if camera_info is not None:
        if (camera_info.width, camera_info.height) not in ((width, height), (0, 0)):
            raise AdapterError(f"CameraInfo is for {camera_info.width}x{camera_info.height} images, the image is "
                               f"{width}x{height}")
        intrinsics = camera_info_intrinsics(camera_info)
    return ViewInput(rgb, alpha, decoded["mask"], decoded["depth"], intrinsics,
                     None if gravity_up is None else np.asarray(gravity_up, dtype=np.float64), roi)
