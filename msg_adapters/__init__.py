"""ROS messages <-> numpy: images, compressed images, camera info, poses, pose arrays and RViz markers.

Imports numpy, OpenCV and the ROS message packages only (no torch, no idpose_core), so the
node's message handling can be tested and reused without a model.
"""

from msg_adapters.camera_info import camera_info_to_matrix
from msg_adapters.compressed import compressed_to_rgb
from msg_adapters.encodings import Encoding, lookup_encoding
from msg_adapters.errors import AdapterError
from msg_adapters.images import array_to_image, image_to_array, image_to_rgb
from msg_adapters.markers import camera_markers
from msg_adapters.poses import matrix_to_pose, pose_to_matrix, poses_to_pose_array

__all__ = [
    "AdapterError",
    "Encoding",
    "array_to_image",
    "camera_info_to_matrix",
    "camera_markers",
    "compressed_to_rgb",
    "image_to_array",
    "image_to_rgb",
    "lookup_encoding",
    "matrix_to_pose",
    "pose_to_matrix",
    "poses_to_pose_array",
]
