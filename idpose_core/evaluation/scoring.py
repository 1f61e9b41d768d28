"""Scoring an estimate against the true cameras, and the random-pose baseline on the same pairs.

True cameras are OpenGL camera-to-world matrices in the object frame (``object_frame``); relative radii
are in Zero-1-to-3 units (the anchor's distance is ``ZERO123_RADIUS``), for the predicted and the true
poses alike, as ``idpose_core.metrics`` expects.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from idpose_core.cameras import ZERO123_RADIUS, c2w_to_spherical, relative_spherical
from idpose_core.evaluation.object_frame import world_cameras
from idpose_core.metrics import camera_errors, random_pose_errors

RANDOM_DRAWS = 200  # random-pose guesses per scored pair: the baseline row of a report


def to_zero123_radius(rel_sph: np.ndarray, anchor_distance: float, radius_scale: float = ZERO123_RADIUS) -> np.ndarray:
    """Relative poses (..., 3) with the radius in world units -> radius in Zero-1-to-3 units."""
    rel_sph = np.array(rel_sph, dtype=np.float64)
    rel_sph[..., 2] *= radius_scale / anchor_distance
    return rel_sph


def score_poses(poses: np.ndarray, true_c2w: np.ndarray, radius_scale: float = ZERO123_RADIUS
                ) -> list[dict[str, object]]:
    """Per target view: predicted and true relative spherical poses and the paper's errors, JSON-ready.

    ``poses`` (n, 4, 4): the estimate, camera k's optical frame in the anchor's (poses[0] = identity);
    ``true_c2w`` (n, 4, 4) OpenGL camera-to-world in the object frame, the anchor first. The estimated
    cameras are placed by the anchor's true pose, so the rotation error counts roll as well, and the
    position error counts the estimate's metric scale (its object distance).
    """
    true_c2w = np.asarray(true_c2w, dtype=np.float64)
    if len(poses) != len(true_c2w):
        raise ValueError(f"{len(poses)} estimated poses for {len(true_c2w)} cameras")
    pred_c2w = world_cameras(poses, true_c2w[0])
    anchor_distance = float(c2w_to_spherical(true_c2w[0])[2])
    rel = [to_zero123_radius(relative_spherical(true_c2w[:1], c2w[1:]), anchor_distance, radius_scale)
           for c2w in (pred_c2w, true_c2w)]
    rot_err, pos_err = camera_errors(pred_c2w[1:], true_c2w[1:], anchor_distance)
    return [
        {"pred_rel_sph": pred.tolist(), "true_rel_sph": true.tolist(), "rot_err_deg": float(rot), "pos_err": float(pos)}
        for pred, true, rot, pos in zip(*rel, rot_err, pos_err)
    ]


def random_baseline(true_c2w: np.ndarray, seed: Sequence[int]) -> list[dict[str, Any]]:
    """``RANDOM_DRAWS`` uniform guesses of each of the views 1..n-1 of one estimate (anchor first), scored."""
    n = len(true_c2w)
    rot, pos = random_pose_errors(np.repeat(true_c2w[:1], n - 1, axis=0), true_c2w[1:], RANDOM_DRAWS,
                                  np.random.default_rng(list(seed)))
    return [{"n": n, "rot_err_deg": r, "pos_err": p} for r, p in zip(rot.ravel(), pos.ravel())]
