"""Poses of views with depth chosen among hypotheses from every source by one verifier.

For every pair of views with object points: the sources propose (``sources``), local registration refines and
the verifier scores (``pair``), and the views are placed jointly (``chain``). A view's pose is ``ambiguous`` when
the runner-up from another cluster scores within ``ambiguity_margin``; a view without depth keeps its diffusion
pose, and says so. No ROS here.
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import small_gicp

from idpose_core.depth_fusion.clouds import ObjectCloud, fused_cloud, view_cloud
from idpose_core.depth_fusion.refinement import (
    VOXEL_RANGE,
    VOXEL_SHARE,
    DepthRefinement,
    ViewRefinement,
    depth_seed,
    pose_change,
)
from idpose_core.depth_fusion.registration import alignment_quality
from idpose_core.pose_hypotheses.chain import choose_poses
from idpose_core.pose_hypotheses.hypothesis import FAR_STAGES, Hypothesis, Source
from idpose_core.pose_hypotheses.pair import PairRanking, Priors, prepare_pair, rank_pair
from idpose_core.pose_hypotheses.sources import arm_hypotheses, arm_pose, gravity_hypotheses, registration_hypotheses
from idpose_core.pose_hypotheses.verifier import ViewEvidence, view_evidence
from idpose_core.segmentation import DepthSegmentationError, Plane, backproject, object_centre, support_plane
from idpose_core.view_input import ViewInput

ALL_SOURCES = frozenset(Source)


@dataclass(frozen=True)
class VerificationSettings:
    """Which ``sources`` propose poses (the diffusion's are always kept: they are what a view without depth
    gets); ``ambiguity_margin``: a view whose best pose leads the runner-up of another cluster by less is
    ambiguous, and so is one whose pose-graph loop residual exceeds ``max_loop_residual_deg`` (the views
    disagree); ``ambiguity_margin_without_gravity``: the lead a view needs when it or the anchor has no gravity
    (the whole rotation group is then open, and a wrong turn of a smooth object can lead clearly);
    ``moved_margin``: by how much a pose far from the arm's must beat it for the object to count as moved;
    ``diffusion_trust``: the prior a pose near the diffusion answer gets, times the solver's confidence in
    it (how far the loaded model is trusted on this object: the embedded model, at chance on a novel object, 0)."""

    sources: frozenset[Source] = ALL_SOURCES
    ambiguity_margin: float = 0.5
    ambiguity_margin_without_gravity: float = 2.5
    max_loop_residual_deg: float = 10.0
    moved_margin: float = 0.3
    diffusion_trust: float = 0.0


@dataclass(frozen=True)
class ViewData:
    """One view's object points, evidence, object centre and support plane (None where it has none)."""

    cloud: ObjectCloud | None
    evidence: ViewEvidence | None
    centre: np.ndarray | None
    plane: Plane | None
    note: str


def view_data(view: ViewInput, mask: np.ndarray, extent: float | None) -> ViewData:
    """What the verifier uses of a view: nothing, with a note, where its depth does not show the object; its
    surroundings are taken ``extent`` (m, default the view's own object's) around the object."""
    if view.depth is None or view.intrinsics is None:
        return ViewData(None, None, None, None, "no depth: the diffusion pose")
    if view.depth.shape != view.rgb.shape[:2]:
        height, width = view.depth.shape[:2]
        return ViewData(None, None, None, None, f"depth {width}x{height} does not match the image "
                                                f"{view.rgb.shape[1]}x{view.rgb.shape[0]}: the diffusion pose")
    cloud = view_cloud(view, mask)
    if cloud is None:
        return ViewData(None, None, None, None, "no depth on the object: the diffusion pose")
    try:
        centre = object_centre(view, mask)
    except DepthSegmentationError as err:
        return ViewData(None, None, None, None, f"no object centre ({err}): the diffusion pose")
    points, valid = backproject(view.depth, view.intrinsics)
    try:
        plane = support_plane(points[valid], view.gravity_up, np.random.default_rng(0))
    except DepthSegmentationError:
        plane = None
    evidence = view_evidence(points, valid, view.intrinsics, view.rgb, mask, centre, extent or cloud.extent())
    return ViewData(cloud, evidence, centre, plane, "")


def pair_priors(views: Sequence[ViewInput], seeds: np.ndarray, confidence: np.ndarray, target: int, source: int,
                settings: VerificationSettings) -> Priors:
    """What the poses of view ``source`` in view ``target`` get before the verifier speaks: the arm's measured
    pose (where both views carry a ``camera_pose`` and the arm's source is on) and the diffusion answer (``seeds``
    (N, 2, 4, 4), NaN where none) weighted by ``diffusion_trust`` and the two views' ``confidence`` (N,)."""
    pose_source, pose_target = views[source].camera_pose, views[target].camera_pose
    arm = None
    if Source.ARM in settings.sources and pose_source is not None and pose_target is not None:
        arm = arm_pose(pose_source, pose_target)
    diffusion = np.linalg.inv(seeds[target, 0]) @ seeds[source, 0]
    if not np.all(np.isfinite(diffusion)):
        return Priors(arm)
    return Priors(arm, diffusion, settings.diffusion_trust * float(min(confidence[target], confidence[source])))


def pair_hypotheses(views: Sequence[ViewInput], data: Sequence[ViewData], seeds: np.ndarray, target: int,
                    source: int, extent: float, settings: VerificationSettings,
                    arm: np.ndarray | None) -> list[Hypothesis]:
    """Every enabled source's proposals for view ``source`` in view ``target``'s frame; ``seeds`` (N, 2, 4, 4):
    each view's diffusion answer and runner-up placed on its depth (NaN where it has none); ``arm``: the arm's
    measured pose (None without it)."""
    first, second = data[target], data[source]
    hypotheses = []
    for option in range(seeds.shape[1]):
        relative = np.linalg.inv(seeds[target, option if target else 0]) @ seeds[source, option]
        if np.all(np.isfinite(relative)):
            hypotheses.append(Hypothesis(relative, Source.DIFFUSION, FAR_STAGES))
    if Source.REGISTRATION in settings.sources:
        hypotheses += registration_hypotheses(second.cloud.points, first.cloud.points, extent)
    up_source, up_target = views[source].gravity_up, views[target].gravity_up
    if Source.GRAVITY in settings.sources and up_source is not None and up_target is not None:
        planes = (second.plane, first.plane) if second.plane is not None and first.plane is not None else None
        hypotheses += gravity_hypotheses(second.cloud.points, first.cloud.points, up_source, up_target,
                                         second.centre, first.centre, extent, planes)
    if arm is not None:
        hypotheses += arm_hypotheses(arm)
    return hypotheses


def object_moved(ranking: PairRanking, extent: float, settings: VerificationSettings) -> bool:
    """Whether the object likely moved between the pair's views: the best pose, with the arm's prior, still lies
    beyond the arm's error from the pose it measured, and the object's own points (the surroundings stood still
    and may well agree with the arm) favour it over every pose near the arm's by ``moved_margin``."""
    priors = ranking.priors
    if priors.arm is None or priors.near_arm(ranking.best.transform, extent):
        return False
    near = [h.object_score for h in ranking.scored if priors.near_arm(h.transform, extent)]
    return ranking.best.object_score - max(near, default=-math.inf) >= settings.moved_margin


def verify_with_depth(views: Sequence[ViewInput], masks: Sequence[np.ndarray], poses: np.ndarray,
                      runner_up_poses: np.ndarray, cloud_voxel_size: float,
                      settings: VerificationSettings = VerificationSettings(),
                      confidence: np.ndarray | None = None,
                      fuse: Sequence[bool] | None = None) -> DepthRefinement | None:
    """Choose the poses (N, 4, 4, anchor's optical frame) of views with depth among every source's hypotheses, and
    their runner-ups; ``poses`` and ``runner_up_poses`` are the diffusion's answers and runner-ups (NaN where none),
    which views without depth keep, and ``confidence`` (N,) the solver's in each answer (the anchor's 1; None: no
    confidence, the diffusion answer gets no prior). The fused cloud holds the anchor and the views placed
    unambiguously that ``fuse`` (N,) allows (all when None: a view whose mask is unsure stays out). None when the
    anchor shows no object depth."""
    poses = np.asarray(poses, dtype=np.float64)
    anchor = view_data(views[0], masks[0], None)
    if anchor.evidence is None:
        return None
    extent = anchor.cloud.extent()
    voxel = float(np.clip(VOXEL_SHARE * extent, *VOXEL_RANGE))
    data = [anchor] + [view_data(view, mask, extent) for view, mask in zip(views[1:], masks[1:])]
    seeds = np.full((len(views), 2, 4, 4), math.nan)
    for k, item in enumerate(data):
        if item.centre is not None:
            for option, diffusion in enumerate((poses[k], np.asarray(runner_up_poses[k], np.float64))):
                if np.all(np.isfinite(diffusion)):
                    seeds[k, option] = depth_seed(diffusion, data[0].centre, item.centre)
    with_depth = [k for k, item in enumerate(data) if item.evidence is not None]
    trust_in = np.zeros(len(views)) if confidence is None else np.asarray(confidence, np.float64)
    rankings = {}
    for target, source in itertools.combinations(with_depth, 2):
        priors = pair_priors(views, seeds, trust_in, target, source, settings)
        hypotheses = pair_hypotheses(views, data, seeds, target, source, extent, settings, priors.arm)
        pair = prepare_pair(data[source].cloud.points, data[target].cloud.points, voxel, extent)
        rankings[(target, source)] = rank_pair(data[target].evidence, data[source].evidence, pair, hypotheses,
                                               priors)
    chosen = choose_poses([item.evidence for item in data], rankings, extent, voxel)
    current = poses.copy()
    runners = np.array(runner_up_poses, dtype=np.float64)
    reports = [ViewRefinement(False, "the anchor", math.nan, math.nan, 0.0, 0.0)]
    anchor_tree = small_gicp.KdTree(small_gicp.PointCloud(data[0].cloud.points))
    for k in range(1, len(views)):
        if k not in chosen:
            reports.append(ViewRefinement(False, data[k].note, math.nan, math.nan, 0.0, 0.0))
            continue
        pick = chosen[k]
        current[k], runners[k] = pick.pose, pick.runner_up
        fitness, rmse = alignment_quality(data[k].cloud.points, anchor_tree, pick.pose, 2.0 * voxel)
        rotation, translation = pose_change(pick.pose, poses[k])
        loop = pick.loop_residual_deg
        gravity = views[0].gravity_up is not None and views[k].gravity_up is not None
        margin = settings.ambiguity_margin if gravity else settings.ambiguity_margin_without_gravity
        ambiguous = bool(pick.margin < margin or loop > settings.max_loop_residual_deg)
        note = ""
        if pick.margin < margin:
            note = f"runner-up within {pick.margin:.2f} of the best" + (
                "" if gravity else f" (without gravity the best must lead by {margin:g})")
        elif ambiguous:
            note = f"the views disagree by {loop:.0f} deg"
        reports.append(ViewRefinement(True, note, fitness, rmse, rotation, translation, pick.source.value,
                                      pick.margin, ambiguous, object_moved(rankings[(0, k)], extent, settings), loop))
    kept = [k for k in range(len(views)) if k == 0 or (reports[k].refined and not reports[k].ambiguous
                                                       and (fuse is None or fuse[k]))]
    cloud = fused_cloud([data[k].cloud for k in kept], [current[k] for k in kept], cloud_voxel_size)
    return DepthRefinement(poses=current, views=reports, cloud=cloud, voxel_size=voxel, runner_up_poses=runners)
