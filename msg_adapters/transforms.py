"""A PoseArray as TF transforms: each pose becomes parent -> child, for a TF broadcaster."""
from collections.abc import Sequence

from geometry_msgs.msg import PoseArray, Transform, TransformStamped, Vector3

from msg_adapters.errors import AdapterError


def pose_array_to_transforms(poses: PoseArray, child_frames: Sequence[str]) -> list[TransformStamped]:
    """One TransformStamped per pose, from the array's frame to ``child_frames[k]``, with the array's stamp."""
    if len(child_frames) != len(poses.poses):
        raise AdapterError(f"{len(poses.poses)} poses but {len(child_frames)} child frames")
    if not poses.header.frame_id:
        raise AdapterError("the poses have no frame_id to be the transforms' parent")
    transforms = []
    for pose, child in zip(poses.poses, child_frames):
        if not child or child == poses.header.frame_id:
            raise AdapterError(f"child frame {child!r} must be non-empty and differ from the parent frame")
        translation = Vector3(x=pose.position.x, y=pose.position.y, z=pose.position.z)
        transforms.append(TransformStamped(header=poses.header, child_frame_id=child,
                                           transform=Transform(translation=translation, rotation=pose.orientation)))
    return transforms
