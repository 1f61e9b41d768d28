"""ROS messages <-> numpy: images, depth and masks, compressed images, poses, pose arrays, TF transforms, RViz
markers, coloured point clouds, and what sensors say about a view (intrinsics, gravity, orientation).

Imports numpy, OpenCV and the ROS message packages only (no torch, no idpose_core), so the
node's message handling can be tested and reused without a model.
"""

from msg_adapters.camera_info import camera_info_to_matrix, matrix_to_camera_info
from msg_adapters.compressed import compressed_to_rgb
from msg_adapters.depth import depth_to_image, image_to_depth, image_to_mask
from msg_adapters.encodings import Encoding, lookup_encoding
from msg_adapters.errors import AdapterError
from msg_adapters.headers import stamp_nanoseconds
from msg_adapters.image_size import ImageTooLarge, encoded_size
from msg_adapters.images import array_to_image, image_to_array, image_to_rgb
from msg_adapters.markers import box_marker, camera_markers
from msg_adapters.point_clouds import cloud_to_points, points_to_cloud
from msg_adapters.poses import matrix_to_pose, pose_to_matrix, poses_to_pose_array
from msg_adapters.sensors import imu_acceleration, orientation_rotation
from msg_adapters.transforms import pose_array_to_transforms
from msg_adapters.validation import check_image

__all__ = [
    "AdapterError",
    "Encoding",
    "ImageTooLarge",
    "array_to_image",
    "box_marker",
    "camera_info_to_matrix",
    "camera_markers",
    "check_image",
    "cloud_to_points",
    "compressed_to_rgb",
    "depth_to_image",
    "encoded_size",
    "image_to_array",
    "image_to_depth",
    "image_to_mask",
    "image_to_rgb",
    "imu_acceleration",
    "lookup_encoding",
    "matrix_to_camera_info",
    "matrix_to_pose",
    "pose_array_to_transforms",
    "orientation_rotation",
    "points_to_cloud",
    "pose_to_matrix",
    "poses_to_pose_array",
    "stamp_nanoseconds",
]
