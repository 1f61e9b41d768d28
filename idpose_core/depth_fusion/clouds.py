"""A view's object points from its masked depth, and several views' points fused in the anchor's frame."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import small_gicp

from idpose_core.segmentation import backproject
from idpose_core.view_input import ViewInput

EDGE_EROSION_PX = 2  # px taken off the mask's edge: readings there mix object and background (flying pixels)
MIN_CLOUD_POINTS = 50  # a view with fewer object readings has no cloud


@dataclass(frozen=True)
class ObjectCloud:
    """``points`` (M, 3) float64 metres in one camera's optical frame and their ``colours`` (M, 3) uint8 RGB."""

    points: np.ndarray
    colours: np.ndarray

    def transformed(self, pose: np.ndarray) -> ObjectCloud:
        """The cloud in the frame where ``pose`` (4, 4) places its camera."""
        pose = np.asarray(pose, dtype=np.float64)
        return ObjectCloud(self.points @ pose[:3, :3].T + pose[:3, 3], self.colours)

    def extent(self) -> float:
        """The cloud's size: the diagonal of its axis-aligned box, 2nd to 98th percentile (m)."""
        low, high = np.percentile(self.points, [2, 98], axis=0)
        return float(np.linalg.norm(high - low))


def view_cloud(view: ViewInput, mask: np.ndarray) -> ObjectCloud | None:
    """The object's depth readings inside ``mask`` (H, W) bool, its edge eroded by ``EDGE_EROSION_PX``, as points in
    the view's optical frame; None without depth, intrinsics or ``MIN_CLOUD_POINTS`` readings."""
    if view.depth is None or view.intrinsics is None:
        return None
    points, valid = backproject(view.depth, view.intrinsics)
    kernel = np.ones((2 * EDGE_EROSION_PX + 1,) * 2, np.uint8)
    inner = cv2.erode(np.asarray(mask, dtype=np.uint8), kernel).astype(bool) & valid
    if inner.sum() < MIN_CLOUD_POINTS:
        return None
    return ObjectCloud(points[inner], view.rgb[inner])


def fused_cloud(clouds: Sequence[ObjectCloud], poses: Sequence[np.ndarray], voxel_size: float) -> ObjectCloud:
    """The clouds put in one frame by ``poses`` (each camera's (4, 4) in that frame) and thinned to one point per
    ``voxel_size`` (m) cell (small_gicp's voxel grid); each kept point takes the colour of its nearest reading."""
    placed = [cloud.transformed(pose) for cloud, pose in zip(clouds, poses)]
    points = np.concatenate([cloud.points for cloud in placed])
    colours = np.concatenate([cloud.colours for cloud in placed])
    thinned = small_gicp.voxelgrid_sampling(points, voxel_size).points()[:, :3]
    tree = small_gicp.KdTree(small_gicp.PointCloud(points))
    nearest, _ = tree.batch_nearest_neighbor_search(thinned)
    return ObjectCloud(np.ascontiguousarray(thinned), colours[np.asarray(nearest)])
