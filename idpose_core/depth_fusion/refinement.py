"""The diffusion poses refined with depth: each view's object points registered into the anchor's frame.

The diffusion estimate is a look-at model: every camera on a sphere, aimed at the object's centre. Depth gives
each view's real object centre, so the seed keeps the diffusion rotation (turned for a camera aimed beside the
object) and puts the view where its centre meets the anchor's; registration then finds the camera's metric
6-DoF pose (generalized ICP). With more than two views, each view is registered again onto the others' fused
points (a joint refinement). A view keeps its refined pose only if the registration fits (fitness, inlier RMSE)
and stays within a trust region of its seed; otherwise it keeps the diffusion pose, and its ``ViewRefinement``
says why.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from idpose_core.depth_fusion.clouds import ObjectCloud, fused_cloud, view_cloud
from idpose_core.depth_fusion.registration import POLISH, SCHEDULES, Registration, register
from idpose_core.metrics import rotation_angle_deg
from idpose_core.segmentation import DepthSegmentationError, object_centre
from idpose_core.view_input import ViewInput

VOXEL_SHARE = 1.0 / 40.0  # of the anchor cloud's extent: the registration's voxel, so any object size works alike
VOXEL_RANGE = (0.001, 0.02)  # m: the voxel stays within these


@dataclass(frozen=True)
class RefinementSettings:
    """The gate: a refined pose is kept when the registration's ``fitness`` reaches ``min_fitness``, its inlier RMSE
    is at most ``max_rmse_voxels`` voxels, and it turns the camera at most ``max_rotation_change_deg`` and moves it at
    most ``max_translation_share`` of the anchor's object distance from its seed. ``joint_rounds``: with more than two
    views, how many times each view is registered again onto all the others."""

    min_fitness: float = 0.3
    max_rmse_voxels: float = 0.95
    max_rotation_change_deg: float = 35.0
    max_translation_share: float = 0.5
    joint_rounds: int = 2


@dataclass(frozen=True)
class ViewRefinement:
    """What depth did to one view's pose: ``refined`` (the pose is the registration's), ``note`` (why not, or
    empty), the registration's ``fitness`` and ``inlier_rmse`` (m; NaN where none ran), and how far the pose moved
    from the diffusion pose (``rotation_change_deg``, ``translation_change`` in m; 0 when not refined).

    Where the pose hypotheses and their verifier chose the pose (``idpose_core.pose_hypotheses``): ``source``, the
    winner's (``diffusion``, ``registration``, ``gravity``, ``arm``; ``diffusion`` too for a view the refinement
    only seeded from it), the verifier's ``margin`` over the runner-up from another cluster (NaN where no verifier
    ran), ``ambiguous`` when that margin is too small to tell them apart (or the views disagree: a pose graph's
    ``loop_residual_deg`` over its bound, NaN with two views or no verifier), and ``object_moved`` when the arm's
    pose lost clearly to another: the object likely moved between the views."""

    refined: bool
    note: str
    fitness: float
    inlier_rmse: float
    rotation_change_deg: float
    translation_change: float
    source: str = "diffusion"
    margin: float = math.nan
    ambiguous: bool = False
    object_moved: bool = False
    loop_residual_deg: float = math.nan


@dataclass(frozen=True)
class DepthRefinement:
    """``poses`` (N, 4, 4): each camera in the anchor's optical frame, refined where ``views[k].refined``, else the
    diffusion pose; ``cloud``: the anchor's and the refined views' object points, fused in the anchor's frame;
    ``voxel_size`` (m) the registration used (the cloud has its own); ``runner_up_poses`` (N, 4, 4): where a
    verifier chose the poses (``idpose_core.pose_hypotheses``), each view's runner-up (the verifier's best pose of
    another cluster, NaN where none; the diffusion's for a view it did not pose); None from ``refine_with_depth``."""

    poses: np.ndarray
    views: list[ViewRefinement]
    cloud: ObjectCloud
    voxel_size: float
    runner_up_poses: np.ndarray | None = None


def aimed_at(ray: np.ndarray) -> np.ndarray:
    """The rotation (3, 3) that turns the optical axis onto ``ray`` (3,) by the shortest way: the frame of a camera
    aimed at the object, as the diffusion model sees it, in the real camera's frame."""
    direction = ray / np.linalg.norm(ray)
    rotation, _ = Rotation.align_vectors([direction], [[0.0, 0.0, 1.0]])
    return rotation.as_matrix()


def depth_seed(diffusion_pose: np.ndarray, anchor_centre: np.ndarray, view_centre: np.ndarray) -> np.ndarray:
    """The registration's start (4, 4): the diffusion rotation between cameras aimed at the object, turned into the
    real cameras (aimed where they were), placed so that the view's object centre meets the anchor's."""
    rotation = aimed_at(anchor_centre) @ diffusion_pose[:3, :3] @ aimed_at(view_centre).T
    seed = np.eye(4)
    seed[:3, :3] = rotation
    seed[:3, 3] = anchor_centre - rotation @ view_centre
    return seed


def pose_change(pose: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    """(rotation in degrees, camera displacement in m) from ``reference`` to ``pose`` (both (4, 4))."""
    rotation = float(rotation_angle_deg(pose[:3, :3], reference[:3, :3]))
    return rotation, float(np.linalg.norm(pose[:3, 3] - reference[:3, 3]))


def gate(registration: Registration, seed: np.ndarray, voxel_size: float, distance: float,
         settings: RefinementSettings) -> str:
    """Why the registration may not replace the seed; empty when it passes."""
    rotation, translation = pose_change(registration.transform, seed)
    if registration.fitness < settings.min_fitness:
        return f"depth registration rejected: fitness {registration.fitness:.2f} < {settings.min_fitness:.2f}"
    if not registration.inlier_rmse <= settings.max_rmse_voxels * voxel_size:
        return (f"depth registration rejected: inlier RMSE {1000 * registration.inlier_rmse:.1f} mm > "
                f"{1000 * settings.max_rmse_voxels * voxel_size:.1f} mm")
    if rotation > settings.max_rotation_change_deg:
        return (f"depth registration rejected: it turns the camera {rotation:.0f} deg from its seed "
                f"(trust region {settings.max_rotation_change_deg:.0f} deg)")
    if translation > settings.max_translation_share * distance:
        return (f"depth registration rejected: it moves the camera {translation:.2f} m from its seed "
                f"(trust region {settings.max_translation_share * distance:.2f} m)")
    return ""


def refine_with_depth(views: Sequence[ViewInput], masks: Sequence[np.ndarray], poses: np.ndarray,
                      cloud_voxel_size: float, settings: RefinementSettings = RefinementSettings(),
                      fuse: Sequence[bool] | None = None) -> DepthRefinement | None:
    """Refine the diffusion ``poses`` (N, 4, 4, in the anchor's optical frame) of the ``views`` with their depth
    inside ``masks`` (each (H_k, W_k) bool in its view's image); the fused cloud holds the anchor and the refined
    views that ``fuse`` (N,) allows (all when None), thinned to ``cloud_voxel_size`` (m). None when the anchor has
    no usable depth: nothing to register onto. Views without depth keep their diffusion pose."""
    poses = np.asarray(poses, dtype=np.float64)
    clouds = [view_cloud(view, mask) for view, mask in zip(views, masks)]
    if clouds[0] is None:
        return None
    centres = []
    for view, mask, cloud in zip(views, masks, clouds):
        try:
            centres.append(None if cloud is None else object_centre(view, mask))
        except DepthSegmentationError:
            centres.append(None)
    extent = clouds[0].extent()
    voxel = float(np.clip(VOXEL_SHARE * extent, *VOXEL_RANGE))
    distance = float(np.linalg.norm(centres[0]))
    seeds = [poses[k] if centres[k] is None else depth_seed(poses[k], centres[0], centres[k])
             for k in range(len(views))]
    current = poses.copy()
    reports = [ViewRefinement(False, "the anchor", math.nan, math.nan, 0.0, 0.0)]
    reports += [ViewRefinement(False, "no depth on the object", math.nan, math.nan, 0.0, 0.0)] * (len(views) - 1)
    rounds = 1 + (settings.joint_rounds if len(views) > 2 else 0)
    for round_index in range(rounds):
        for k in range(1, len(views)):
            if clouds[k] is None:
                continue
            partners = [0] if round_index == 0 else [j for j in range(len(views)) if j != k and
                                                     (j == 0 or reports[j].refined)]
            target = np.concatenate([clouds[j].transformed(current[j]).points for j in partners])
            start, schedules = (current[k], POLISH) if reports[k].refined else (seeds[k], SCHEDULES)
            registration = register(clouds[k].points, target, start, voxel, extent, schedules,
                                    settings.max_rotation_change_deg)
            note = gate(registration, seeds[k], voxel, distance, settings)
            if note and reports[k].refined:
                continue  # a later round that fails the gate leaves the earlier refined pose
            if not note:
                current[k] = registration.transform
            rotation, translation = pose_change(current[k], poses[k]) if not note else (0.0, 0.0)
            reports[k] = ViewRefinement(not note, note, registration.fitness, registration.inlier_rmse,
                                        rotation, translation)
    kept = [k for k in range(len(views)) if k == 0 or (reports[k].refined and (fuse is None or fuse[k]))]
    cloud = fused_cloud([clouds[k] for k in kept], [current[k] for k in kept], cloud_voxel_size)
    return DepthRefinement(poses=current, views=reports, cloud=cloud, voxel_size=voxel)
