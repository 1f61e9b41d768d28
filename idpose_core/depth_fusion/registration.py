"""One view's object points registered onto another's: generalized ICP (small_gicp), coarse to fine.

GICP, not point-to-plane ICP: on the tabletop views of the six demo objects, from seeds 15 deg off, it
lands within 5 deg for 11 of 12 pairs where point-to-plane ICP does for 7 (a partial view's planes let it slide).
Geometry alone cannot tell a smooth object's turns apart: the gate in ``refinement`` and the diffusion seed do.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import small_gicp

from idpose_core.metrics import rotation_angle_deg

NEIGHBOURS = 10  # points for each normal
ITERATIONS = 40  # per stage
# Shares of the object's extent: how far apart points may match, stage by stage. Far matches pull a seed 15-30 deg
# off into place, but can drag a seed that is already right off it where the views overlap in part (a smooth
# object slides); every schedule runs, and of those that fit about as well as the best (``FITNESS_SLACK``) the one
# nearest the seed wins.
SCHEDULES = ((0.25, 0.1, 0.05, 0.025), (0.1, 0.05, 0.025), (0.05, 0.025), (0.025,))
# A pose registration already found is only polished: far matches onto other views' points would let a smooth or
# symmetric object slide off it (a mug turned about its axis fits the fused points as well).
POLISH = SCHEDULES[-1:]
FITNESS_SLACK = 0.05


@dataclass(frozen=True)
class Registration:
    """``transform`` (4, 4): the source's frame in the target's; ``fitness``: the share of source points with a
    target point within the inlier distance; ``inlier_rmse``: their root-mean-square distance (m)."""

    transform: np.ndarray
    fitness: float
    inlier_rmse: float


def register(source: np.ndarray, target: np.ndarray, initial: np.ndarray, voxel_size: float, extent: float,
             schedules: Sequence[tuple[float, ...]] = SCHEDULES, max_turn_deg: float = 180.0) -> Registration:
    """Register ``source`` (M, 3) onto ``target`` (K, 3) from ``initial`` (4, 4, source frame in target frame):
    GICP on clouds thinned to ``voxel_size``, for each of the ``schedules`` matching points up to its shares of the
    object's ``extent`` (m) apart, from far to near; of the fits within ``FITNESS_SLACK`` of the best fitness
    (measured at 2 voxels), the one that turns the source least from ``initial`` wins. Fits that turn it more than
    ``max_turn_deg`` (the caller's trust region) compete only when no fit stays within it: a far slide that fits
    better must not hide a fit inside the trust region."""
    target_cloud, target_tree = small_gicp.preprocess_points(target, voxel_size, num_neighbors=NEIGHBOURS)
    source_cloud, _ = small_gicp.preprocess_points(source, voxel_size, num_neighbors=NEIGHBOURS)
    found = []
    for schedule in schedules:
        transform = np.asarray(initial, dtype=np.float64)
        for share in schedule:
            result = small_gicp.align(target_cloud, source_cloud, target_tree, init_T_target_source=transform,
                                      registration_type="GICP", max_correspondence_distance=share * extent,
                                      max_iterations=ITERATIONS)
            transform = np.asarray(result.T_target_source)
        fitness, rmse = alignment_quality(source_cloud.points()[:, :3], target_tree, transform, 2.0 * voxel_size)
        found.append(Registration(transform, fitness, rmse))
    turns = rotation_angle_deg(np.stack([registration.transform[:3, :3] for registration in found]),
                               np.asarray(initial)[:3, :3])
    trusted = [k for k in range(len(found)) if turns[k] <= max_turn_deg] or list(range(len(found)))
    best = max(found[k].fitness for k in trusted)
    near = [k for k in trusted if found[k].fitness >= best - FITNESS_SLACK]
    return found[min(near, key=lambda k: turns[k])]


def alignment_quality(source: np.ndarray, target_tree: small_gicp.KdTree, transform: np.ndarray,
                      inlier_distance: float) -> tuple[float, float]:
    """(fitness, inlier RMSE in m) of ``source`` (M, 3) placed by ``transform`` against the target's tree."""
    placed = source @ transform[:3, :3].T + transform[:3, 3]
    _, squared = target_tree.batch_nearest_neighbor_search(placed)
    squared = np.asarray(squared, dtype=np.float64)
    inliers = squared <= inlier_distance ** 2
    if not inliers.any():
        return 0.0, float("nan")
    return float(inliers.mean()), float(np.sqrt(squared[inliers].mean()))
