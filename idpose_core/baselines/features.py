"""The two-view feature baseline: SIFT, Lowe's ratio test, the essential matrix (RANSAC) and ``recoverPose``
for each anchor-target pair, with known intrinsics. A pair with too few inliers has no pose.
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from idpose_core.baselines.result import BaselineEstimate, scale_to_object_distance, status_of

RATIO = 0.75  # Lowe's ratio test
MIN_INLIERS = 15  # as COLMAP's two-view verification (min_num_inliers)
RANSAC_THRESHOLD_PX = 1.0
RANSAC_CONFIDENCE = 0.999
Features = tuple[np.ndarray, np.ndarray | None]  # keypoint positions (K, 2), descriptors (K, 128) or None


@dataclass(frozen=True)
class TwoViewPose:
    """The second camera in the first one's frame: ``pose`` (4, 4) with a unit-length translation;
    ``inliers`` is the number of matches that pass RANSAC and the cheirality check."""

    pose: np.ndarray
    inliers: int


def sift_features(rgb: np.ndarray) -> Features:
    """SIFT keypoint positions (K, 2) and descriptors (K, 128) (None when K = 0) of an RGB uint8 image."""
    keypoints, descriptors = cv2.SIFT_create().detectAndCompute(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY), None)
    return np.array([k.pt for k in keypoints], dtype=np.float64).reshape(-1, 2), descriptors


def ratio_matches(descriptors_a: np.ndarray | None, descriptors_b: np.ndarray | None, ratio: float = RATIO
                  ) -> np.ndarray:
    """Index pairs (M, 2) of the matches a -> b whose nearest neighbour beats the second by ``ratio``."""
    if descriptors_a is None or descriptors_b is None or len(descriptors_b) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    pairs = cv2.BFMatcher(cv2.NORM_L2).knnMatch(descriptors_a, descriptors_b, k=2)
    good = [(m.queryIdx, m.trainIdx) for m, second in pairs if m.distance < ratio * second.distance]
    return np.array(good, dtype=np.int64).reshape(-1, 2)


def two_view_pose(features_a: Features, features_b: Features, camera_matrix: np.ndarray,
                  min_inliers: int = MIN_INLIERS) -> TwoViewPose | None:
    """Relative pose of view b in view a's camera frame (optical axes) from their ``sift_features``, or None
    with fewer than ``min_inliers``."""
    (points_a, descriptors_a), (points_b, descriptors_b) = features_a, features_b
    matches = ratio_matches(descriptors_a, descriptors_b)
    if len(matches) < max(min_inliers, 5):
        return None
    pa, pb = points_a[matches[:, 0]], points_b[matches[:, 1]]
    essential, mask = cv2.findEssentialMat(pa, pb, camera_matrix, method=cv2.RANSAC, prob=RANSAC_CONFIDENCE,
                                           threshold=RANSAC_THRESHOLD_PX)
    if essential is None or essential.shape != (3, 3):
        return None
    inliers, rotation, translation, _ = cv2.recoverPose(essential, pa, pb, camera_matrix, mask=mask)
    if inliers < min_inliers:
        return None
    b_from_a = np.eye(4)
    b_from_a[:3, :3], b_from_a[:3, 3] = rotation, translation.ravel()
    return TwoViewPose(np.linalg.inv(b_from_a), int(inliers))


def estimate_features(images: Sequence[np.ndarray], camera_matrix: np.ndarray, object_distance: float,
                      min_inliers: int = MIN_INLIERS) -> BaselineEstimate:
    """Each view's pose from its own pair with the anchor (images[0]), scaled by the anchor's ``object_distance``.

    A pair fails with too few inliers or when the two optical axes locate no object in front of the anchor.
    """
    start = time.perf_counter()
    poses, registered = np.repeat(np.eye(4)[None], len(images), axis=0), np.arange(len(images)) == 0
    anchor = sift_features(images[0])
    for index, image in enumerate(images[1:], start=1):
        pair = two_view_pose(anchor, sift_features(image), camera_matrix, min_inliers)
        scaled = None if pair is None else scale_to_object_distance(np.stack([np.eye(4), pair.pose]),
                                                                    np.ones(2, dtype=bool), object_distance)
        if scaled is not None:
            poses[index], registered[index] = scaled[1], True
    return BaselineEstimate(poses, registered, status_of(registered), time.perf_counter() - start)
