"""The paper's evaluation protocol over a pool of posed views: sampling, the object frame, scoring.

From a pool of views with known camera poses, ``draw_picks`` makes seeded picks of 8 views (kept in
capture order); the first 2, 4, 6 and 8 views of each pick are estimated, the first view being the
anchor. True cameras come in the world as ROS optical camera-to-world matrices; ``object_frame_c2w``
moves them into the object's spherical frame (object centre at the origin, world up -> +z) with
OpenGL camera axes, as ``idpose_core.metrics`` expects. Relative radii are in Zero-1-to-3 units
(the anchor's distance is ``ZERO123_RADIUS``), for the predicted and the true poses alike.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from idpose_core.cameras import (
    ZERO123_RADIUS,
    c2w_to_spherical,
    opengl_to_optical,
    relative_spherical,
)
from idpose_core.metrics import camera_errors

PICK_SIZE = 8
VIEW_COUNTS = (2, 4, 6, 8)


@dataclass(frozen=True)
class ViewSetEstimate:
    """What an estimator returns for n views: what the node publishes, and the solver's confidence.

    ``poses`` (n, 4, 4) optical camera poses in the anchor camera's frame (poses[0] = identity);
    ``scores`` and ``ambiguous`` (n-1,) per non-anchor view; ``seconds`` the wall time of the estimate;
    ``details`` what the estimate read off its views (JSON-ready: how masks were made, gravity's polar
    angles and rolls, the depth distance, where the anchor's polar angle and distance came from).
    """

    poses: np.ndarray
    scores: np.ndarray
    ambiguous: np.ndarray
    seconds: float
    details: dict[str, Any] = field(default_factory=dict)


def draw_picks(pool: Sequence[int], samples: int, seed: int, pick_size: int = PICK_SIZE) -> list[list[int]]:
    """``samples`` seeded random picks of ``min(pick_size, len(pool))`` distinct view ids, each sorted.

    Sorting keeps the capture order, so the first view of a pick (the anchor) is the one a robot
    would have taken first. Raises ValueError for fewer than 2 views or a non-positive sample count.
    """
    if len(pool) < 2:
        raise ValueError(f"need at least 2 usable views to evaluate, the pool has {len(pool)}")
    if samples < 1:
        raise ValueError(f"the number of samples must be at least 1, got {samples}")
    rng = np.random.default_rng(seed)
    size = min(pick_size, len(pool))
    return [sorted(int(v) for v in rng.choice(np.asarray(pool), size=size, replace=False)) for _ in range(samples)]


def match_stamps(queries: Sequence[int], stamps: Sequence[int], tolerance: int) -> np.ndarray:
    """Index (N,) of the stamp nearest to each query within ``tolerance`` (same unit), or -1 when none is."""
    queries = np.asarray(queries, dtype=np.int64)
    stamps = np.asarray(stamps, dtype=np.int64)
    if stamps.size == 0:
        return np.full(queries.shape, -1, dtype=np.int64)
    order = np.argsort(stamps, kind="stable")
    ordered = stamps[order]
    right = np.clip(np.searchsorted(ordered, queries), 0, len(ordered) - 1)
    left = np.clip(right - 1, 0, len(ordered) - 1)
    nearest = np.where(np.abs(ordered[left] - queries) <= np.abs(ordered[right] - queries), left, right)
    found = np.abs(ordered[nearest] - queries) <= tolerance
    return np.where(found, order[nearest], -1)


def world_to_object(center: Sequence[float], up: Sequence[float]) -> np.ndarray:
    """Rigid transform (4, 4) from the world to the object frame: ``center`` -> origin, ``up`` -> +z.

    The rotation is the smallest one taking ``up`` to +z; the azimuth origin it leaves does not
    matter, since only relative poses are scored. Raises ValueError for a zero ``up``.
    """
    up = np.asarray(up, dtype=np.float64)
    if up.shape != (3,) or np.linalg.norm(up) < 1e-12:
        raise ValueError(f"the up axis must be a non-zero 3-vector, got {up.tolist()}")
    up = up / np.linalg.norm(up)
    z = np.array([0.0, 0.0, 1.0])
    axis, cosine = np.cross(up, z), float(np.dot(up, z))
    if cosine < -1.0 + 1e-12:  # up is -z: half a turn about x
        rotation = np.diag([1.0, -1.0, -1.0])
    else:
        skew = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
        rotation = np.eye(3) + skew + skew @ skew / (1.0 + cosine)
    transform = np.eye(4)
    transform[:3, :3] = rotation
    transform[:3, 3] = -rotation @ np.asarray(center, dtype=np.float64)
    return transform


def object_frame_c2w(world_from_optical: np.ndarray, center: Sequence[float], up: Sequence[float]) -> np.ndarray:
    """True cameras (..., 4, 4) in the world, optical axes -> OpenGL camera-to-world in the object frame."""
    return opengl_to_optical(world_to_object(center, up) @ np.asarray(world_from_optical, dtype=np.float64))


def to_zero123_radius(rel_sph: np.ndarray, anchor_distance: float, radius_scale: float = ZERO123_RADIUS) -> np.ndarray:
    """Relative poses (..., 3) with the radius in world units -> radius in Zero-1-to-3 units."""
    rel_sph = np.array(rel_sph, dtype=np.float64)
    rel_sph[..., 2] *= radius_scale / anchor_distance
    return rel_sph


def world_cameras(poses: np.ndarray, anchor_c2w: np.ndarray) -> np.ndarray:
    """Estimated cameras as OpenGL camera-to-world (N, 4, 4) in the object frame: ``poses`` (N, 4, 4), optical
    frames in the anchor's optical frame (what the node publishes), placed by the anchor's true pose."""
    anchor = opengl_to_optical(np.asarray(anchor_c2w, dtype=np.float64))
    return opengl_to_optical(anchor @ np.asarray(poses, dtype=np.float64))


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
