"""``ViewInput``: one view as the pipeline takes it, the image and whatever else the robot knows about it.

Every field but ``rgb`` is optional; each one the robot provides makes the estimate better informed:
an external ``mask`` or an ``alpha`` channel marks the object, an aligned ``depth`` image with the
camera ``intrinsics`` segments it from its support and measures its distance, and ``gravity_up``
(world up in the camera's optical frame, from an IMU or the arm's kinematics) fixes the view's roll
and elevation; ``camera_pose`` (the camera's optical frame in a fixed frame, from the arm's kinematics or TF)
proposes the relative pose between two views directly. Frames follow REP 103: optical x right, y down, z forward.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


class ViewInputError(ValueError):
    """A view's arrays do not fit together; the message names the view and the field."""


@dataclass(frozen=True)
class ViewInput:
    """One view.

    ``rgb`` (H, W, 3) uint8; ``alpha`` (H, W) uint8 (> 127 = object) from the image's own alpha
    channel; ``mask`` (H, W) bool from an external segmentation (trusted over everything else);
    ``depth`` (H, W) float32 metres aligned to ``rgb`` (0 or NaN = no reading); ``intrinsics`` K (3, 3);
    ``gravity_up`` (3,) unit vector of world up in the optical frame; ``roi`` (x, y, width, height) in
    pixels where the target object is, when several objects are in sight; ``camera_pose`` (4, 4) the optical
    frame in a fixed frame shared by the views (metres).
    """

    rgb: np.ndarray
    alpha: np.ndarray | None = None
    mask: np.ndarray | None = None
    depth: np.ndarray | None = None
    intrinsics: np.ndarray | None = None
    gravity_up: np.ndarray | None = None
    roi: tuple[int, int, int, int] | None = None
    camera_pose: np.ndarray | None = None

    def check(self, name: str = "view 0") -> None:
        """Raise ``ViewInputError`` naming the view (``name``) and the field when an array is malformed."""
        rgb = self.rgb
        if not isinstance(rgb, np.ndarray) or rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
            raise ViewInputError(f"{name}: expected an RGB uint8 array (H, W, 3), got "
                                 f"{getattr(rgb, 'dtype', type(rgb).__name__)} {getattr(rgb, 'shape', '')}")
        shape = rgb.shape[:2]
        for field_name, kinds in (("alpha", (np.uint8,)), ("mask", (np.bool_, np.uint8)), ("depth", (np.float32,))):
            value = getattr(self, field_name)
            if value is not None and (not isinstance(value, np.ndarray) or value.dtype.type not in kinds
                                      or value.shape != shape):
                raise ViewInputError(f"{name}: {field_name} must be {'/'.join(k.__name__ for k in kinds)} {shape}, "
                                     f"got {getattr(value, 'dtype', type(value).__name__)} "
                                     f"{getattr(value, 'shape', '')}")
        if self.intrinsics is not None:
            k = np.asarray(self.intrinsics, dtype=np.float64)
            if k.shape != (3, 3) or not np.all(np.isfinite(k)) or k[0, 0] <= 0 or k[1, 1] <= 0:
                raise ViewInputError(f"{name}: intrinsics must be a finite 3x3 K with positive focal "
                                     f"lengths, got {k.tolist()}")
        if self.gravity_up is not None:
            up = np.asarray(self.gravity_up, dtype=np.float64)
            if up.shape != (3,) or not np.all(np.isfinite(up)) or abs(np.linalg.norm(up) - 1.0) > 1e-3:
                raise ViewInputError(f"{name}: gravity_up must be a unit 3-vector, got {up.tolist()}")
        if self.camera_pose is not None:
            pose = np.asarray(self.camera_pose, dtype=np.float64)
            if (pose.shape != (4, 4) or not np.all(np.isfinite(pose))
                    or not np.allclose(pose[:3, :3] @ pose[:3, :3].T, np.eye(3), atol=1e-3)
                    or not np.allclose(pose[3], [0.0, 0.0, 0.0, 1.0])):
                raise ViewInputError(f"{name}: camera_pose must be a finite rigid 4x4 transform, got {pose.tolist()}")
        if self.roi is not None:
            x, y, width, height = self.roi
            if width <= 0 or height <= 0 or x >= shape[1] or y >= shape[0] or x + width <= 0 or y + height <= 0:
                raise ViewInputError(f"{name}: roi {tuple(self.roi)} does not overlap the "
                                     f"{shape[1]}x{shape[0]} image")

    def principal_point(self) -> tuple[float, float]:
        """(cx, cy) from the intrinsics, else the image centre."""
        if self.intrinsics is not None:
            return float(self.intrinsics[0][2]), float(self.intrinsics[1][2])
        height, width = self.rgb.shape[:2]
        return (width - 1) / 2.0, (height - 1) / 2.0
