"""A view's messages -> the pipeline's ``ViewInput``: image, depth, mask and intrinsics decoded by msg_adapters.

The node and the bag readers both go through these functions, so a view means the same to both. A view read
from a bag keeps its messages (``MessageView``), so that a replay sends them as recorded (``restamped``);
``encode_view`` goes the other way, for a client that has only decoded views.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from std_msgs.msg import Header

from idpose_core.view_input import ViewInput
from msg_adapters import (
    AdapterError,
    array_to_image,
    camera_info_to_matrix,
    compressed_to_rgb,
    depth_to_image,
    image_to_depth,
    image_to_mask,
    image_to_rgb,
    matrix_to_camera_info,
)


@dataclass(frozen=True)
class ViewMessages:
    """One view as messages: its image and the depth, mask and CameraInfo that go with it (None where there is
    none), world up in its optical frame (None without gravity), its optical frame in a fixed frame
    (``camera_pose`` (4, 4), from the arm; None without), and where the node took them: its region of interest
    and the Imu or orientation messages its gravity came from."""

    image: Image | CompressedImage
    depth: Image | None = None
    mask: Image | None = None
    camera_info: CameraInfo | None = None
    gravity_up: np.ndarray | None = None
    roi: tuple[int, int, int, int] | None = None
    gravity_source: tuple[object, ...] = ()
    camera_pose: np.ndarray | None = None


def decode_image(message: Image | CompressedImage, max_pixels: int | None = None
                 ) -> tuple[np.ndarray, np.ndarray | None]:
    """(rgb (H, W, 3) uint8, alpha (H, W) uint8 | None) of an Image or CompressedImage; ``ImageTooLarge`` above
    ``max_pixels`` (checked before decoding)."""
    return (image_to_rgb if isinstance(message, Image) else compressed_to_rgb)(message, max_pixels)


def with_inputs(view: ViewInput, depth: Image | None = None, mask: Image | None = None,
                camera_info: CameraInfo | None = None, gravity_up: np.ndarray | None = None,
                roi: tuple[int, int, int, int] | None = None, camera_pose: np.ndarray | None = None) -> ViewInput:
    """The view with these inputs decoded and added (None keeps what it has); AdapterError names the message
    that does not decode or does not fit the image (depth and mask must be aligned to it: the same width and
    height; so must the CameraInfo). ``camera_pose`` (4, 4): the camera's optical frame in a fixed frame."""
    height, width = view.rgb.shape[:2]
    decoded = {"depth": image_to_depth(depth) if depth is not None else None,
               "mask": image_to_mask(mask) if mask is not None else None}
    for name, array in decoded.items():
        if array is not None and array.shape != (height, width):
            raise AdapterError(f"the {name} image is {array.shape[1]}x{array.shape[0]}, the colour image "
                               f"{width}x{height}: they must be aligned (e.g. aligned_depth_to_color)")
    changes = {name: array for name, array in decoded.items() if array is not None}
    if camera_info is not None:
        if (camera_info.width, camera_info.height) not in ((width, height), (0, 0)):
            raise AdapterError(f"CameraInfo is for {camera_info.width}x{camera_info.height} images, the image is "
                               f"{width}x{height}")
        changes["intrinsics"] = camera_info_to_matrix(camera_info)
    if gravity_up is not None:
        changes["gravity_up"] = np.asarray(gravity_up, dtype=np.float64)
    if roi is not None:
        changes["roi"] = roi
    if camera_pose is not None:
        changes["camera_pose"] = np.asarray(camera_pose, dtype=np.float64)
    return replace(view, **changes)


@dataclass(frozen=True)
class MessageView(ViewInput):
    """A view decoded from messages, with the messages themselves: what a replay sends to the node as recorded."""

    messages: ViewMessages | None = None


def restamped(view: ViewMessages, stamp: Time, frame_id: str) -> ViewMessages:
    """The view's messages as recorded (encodings, compression, data shared), each with a new header: ``stamp``
    in ``frame_id``."""
    def with_header(message: Any) -> Any:
        if message is None:
            return None
        fresh = copy.copy(message)  # shallow: the header would be shared, so it is replaced, not changed
        fresh.header = Header(stamp=stamp, frame_id=frame_id)
        return fresh

    return replace(view, image=with_header(view.image), depth=with_header(view.depth),
                   mask=with_header(view.mask), camera_info=with_header(view.camera_info))


def decode_view(image: Image | CompressedImage, depth: Image | None = None, mask: Image | None = None,
               camera_info: CameraInfo | None = None, gravity_up: np.ndarray | None = None,
               roi: tuple[int, int, int, int] | None = None, camera_pose: np.ndarray | None = None) -> ViewInput:
    """Decode one view and its inputs (``with_inputs``)."""
    return with_inputs(ViewInput(*decode_image(image)), depth, mask, camera_info, gravity_up, roi, camera_pose)


def encode_view(view: ViewInput, stamp: Time, frame_id: str) -> ViewMessages:
    """A decoded view as the messages a camera driver would publish, all stamped ``stamp`` in ``frame_id``: the
    image (rgba8 with its alpha, else rgb8), depth (32FC1 metres), mask (mono8 0/255) and CameraInfo; lossless,
    so ``decode_view`` gives the view back."""
    def header() -> Header:
        return Header(stamp=stamp, frame_id=frame_id)

    height, width = view.rgb.shape[:2]
    image = (array_to_image(np.dstack([view.rgb, view.alpha]), "rgba8", header()) if view.alpha is not None
             else array_to_image(view.rgb, "rgb8", header()))
    depth = depth_to_image(view.depth, "32FC1", header()) if view.depth is not None else None
    mask = (array_to_image(np.where(np.asarray(view.mask, dtype=bool), 255, 0).astype(np.uint8), "mono8", header())
            if view.mask is not None else None)
    camera_info = (matrix_to_camera_info(view.intrinsics, width, height, header()) if view.intrinsics is not None
                   else None)
    return ViewMessages(image, depth, mask, camera_info, view.gravity_up, camera_pose=view.camera_pose)
