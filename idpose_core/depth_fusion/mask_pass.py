"""The masks' second pass across views: once the views are posed, the object's fused cloud says which readings of
each view are the object's. A part one view's cut missed (a head dropped against a wall) comes back where the
cloud, from the other views, reaches it; a view left out of the fusion (its mask unsure) loses what lies beyond
the object's box (the wall its cut joined)."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial import cKDTree

from idpose_core.segmentation import DepthSegmentationError, backproject, support_plane
from idpose_core.segmentation.cut import MIN_HEIGHT, MIN_HEIGHT_SHARE
from idpose_core.segmentation.plane import depth_tolerance
from idpose_core.view_input import ViewInput

SUPPORT_VOXELS = 1.5  # a reading within this many of the cloud's cells of a cloud point is the object's
GROW_REACH_SHARE = 0.5  # of the mask's bounding-box diagonal: how far beyond its edge the mask may grow
BOX_MARGIN_SHARE = 0.15  # of the cloud's extent: the object's box (2nd-98th percentile) grown by this, for trimming


@dataclass(frozen=True)
class MaskPass:
    """One view's ``mask`` (H, W) bool after the pass, and how many pixels it ``added`` and ``removed``."""

    mask: np.ndarray
    added: int = 0
    removed: int = 0

    def note(self, before: int) -> str:
        """What the pass did, as a share of the mask's ``before`` pixels ("" when nothing)."""
        if not (self.added or self.removed):
            return ""
        return (f"the cross-view pass added {self.added} px and removed {self.removed} px "
                f"({100 * (self.added + self.removed) / max(before, 1):.0f} % of the mask)")


def _off_the_table(view: ViewInput, points: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(H, W) bool: the readings that stand above the view's support plane as the depth cut judges it (its
    ``MIN_HEIGHT``), or all of them where the view shows no plane: the table under an object's base is never its."""
    try:
        plane = support_plane(points[valid], view.gravity_up, np.random.default_rng(0))
    except DepthSegmentationError:
        return valid
    depth = np.where(valid, points[..., 2], 0.0)
    return valid & (plane.height(points) > depth_tolerance(depth, MIN_HEIGHT, MIN_HEIGHT_SHARE))


def _points_in_anchor(view: ViewInput, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The view's readings as points (H, W, 3) in the anchor's frame (``pose``: its camera there), where it has
    them and where it has them off the table (both (H, W) bool, ``_off_the_table``)."""
    points, valid = backproject(view.depth, view.intrinsics)
    return points @ pose[:3, :3].T + pose[:3, 3], valid, _off_the_table(view, points, valid)


def _grown(mask: np.ndarray, placed: np.ndarray, valid: np.ndarray, tree: cKDTree, reach: float) -> np.ndarray:
    """The readings outside ``mask`` within ``GROW_REACH_SHARE`` of its size that lie within ``reach`` (m) of the
    cloud (``tree``) and connect to the mask through others that do: the object's, which the view's cut missed."""
    _, _, width, height = cv2.boundingRect(mask.astype(np.uint8))
    grow = max(1, int(round(GROW_REACH_SHARE * np.hypot(width, height))))
    near = cv2.dilate(mask.astype(np.uint8), np.ones((2 * grow + 1,) * 2, np.uint8)).astype(bool) & valid & ~mask
    supported = np.zeros(mask.shape, bool)
    if near.any():
        distance, _ = tree.query(placed[near], distance_upper_bound=reach)
        supported[near] = distance <= reach
    _, labels = cv2.connectedComponents((mask | supported).astype(np.uint8), connectivity=8)
    touching = np.unique(labels[mask])
    return supported & np.isin(labels, touching[touching > 0])


def _beyond_box(mask: np.ndarray, placed: np.ndarray, valid: np.ndarray, cloud: np.ndarray) -> np.ndarray:
    """The mask's readings outside the cloud's box (its 2nd-98th percentile on each axis of the anchor's frame, grown
    by ``BOX_MARGIN_SHARE`` of its extent): what the view's cut joined to the object that the others never saw."""
    low, high = np.percentile(cloud, [2, 98], axis=0)
    margin = BOX_MARGIN_SHARE * float(np.linalg.norm(high - low))
    inside = mask & valid
    beyond = np.zeros(mask.shape, bool)
    beyond[inside] = np.any((placed[inside] < low - margin) | (placed[inside] > high + margin), axis=1)
    return beyond


def cross_view_masks(views: Sequence[ViewInput], masks: Sequence[np.ndarray], poses: np.ndarray, cloud: np.ndarray,
                     voxel_size: float, posed: Sequence[bool], fused: Sequence[bool]) -> list[MaskPass]:
    """Each view's mask after the second pass, from the fused ``cloud`` (M, 3) in the anchor's frame (thinned to
    ``voxel_size`` m) and the ``poses`` (N, 4, 4) of the cameras there: a view ``posed`` (its pose placed by depth and
    trusted) with depth and intrinsics gains the readings the cloud supports (``_grown``); one also left out of the
    fusion (``fused`` False: its mask was unsure) loses those beyond the cloud's box (``_beyond_box``). Other views
    keep their mask."""
    tree = cKDTree(cloud) if len(cloud) else None
    passes = []
    for view, mask, pose, placed_ok, in_cloud in zip(views, masks, poses, posed, fused):
        mask = np.asarray(mask, dtype=bool)
        if tree is None or not placed_ok or view.depth is None or view.intrinsics is None:
            passes.append(MaskPass(mask))
            continue
        placed, valid, off_table = _points_in_anchor(view, np.asarray(pose, dtype=np.float64))
        added = _grown(mask, placed, off_table, tree, SUPPORT_VOXELS * voxel_size)
        removed = np.zeros_like(mask) if in_cloud else _beyond_box(mask, placed, valid, cloud)
        passes.append(MaskPass((mask | added) & ~removed, int(added.sum()), int(removed.sum())))
    return passes
