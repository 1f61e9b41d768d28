"""Views -> camera poses in the anchor frame: the one path the node, the bag evaluator and the demo share.

Turn each view upright (gravity) -> cut out and frame the object (preprocess_views) -> read each
view's elevation (gravity) and the anchor's distance (depth) -> invert the model (estimate_poses)
-> poses of the upright cameras in the anchor frame -> each view's roll put back -> where views have depth,
their poses refined by registering their object points (depth_fusion) and the object's cloud and box. No ROS here.
"""
from __future__ import annotations

import math
import threading
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np
import torch

from idpose_core.cameras import anchor_frame_poses
from idpose_core.depth_fusion import (
    DepthRefinement,
    ObjectFrame,
    ViewRefinement,
    cross_view_masks,
    object_frame,
    refine_with_depth,
)
from idpose_core.deroll import original_frame_mask, upright_view
from idpose_core.gravity import polar_angle, with_roll
from idpose_core.next_view import NextView, ReachableSet, pose_spheres, suggest_next_view, view_spheres
from idpose_core.noise_predictor import NoisePredictor
from idpose_core.pose_hypotheses import VerificationSettings, verify_with_depth
from idpose_core.preprocessing import PreprocessedViews, bounding_box, preprocess_views
from idpose_core.segmentation import DepthSegmentationError, object_distance
from idpose_core.segmentation.confidence import MIN_MASK_CONFIDENCE
from idpose_core.solver import Progress, SampleCount, SolverConfig, SolverResult, estimate_poses
from idpose_core.view_input import ViewInput

__all__ = ["PipelineResult", "PipelineSettings", "ViewInput", "ViewReport", "estimate_details", "estimate_view_poses",
           "result_details", "view_crops", "views_mosaic"]

MODEL_IMAGE_SIZE = 256  # Zero-1-to-3's input side in pixels
LEVEL_POLAR_DEG = 90.0  # the anchor's polar angle when nothing tells it: a level camera
ANCHOR_POLAR_RANGE_DEG = (1.0, 179.0)  # the anchor polar angles accepted: straight above or below has no azimuth
# A mask "touches the border" when it has a pixel within this many pixels of the image's edge (0 = on the
# outermost row or column): 2 px more allows for a mask boundary that stops a pixel or two short of the edge
# (anti-aliasing, depth holes along the frame). Such an object is cut off, and the model compares a part.
BORDER_MARGIN_PX = 2
DEPTH_POSES = ("verify", "refine")  # how depth sets the poses: hypotheses from every source and one verifier, or
# only the diffusion estimate refined by registration


@dataclass(frozen=True)
class PipelineSettings:
    """How to estimate: the solver's settings (``solver.anchor_polar_deg`` is the anchor camera's polar
    angle around the object, None = level; gravity overrides it), the anchor's ``object_distance``
    (metres, the scale of the published positions; depth overrides it) and ``image_size``, the side of
    the preprocessed views the model sees; ``depth_refinement``: set the poses of views with depth from their
    object points, the fused cloud thinned to ``cloud_voxel_size`` (m), as ``depth_poses`` says: "verify" chooses
    among the hypotheses of every source (registration, gravity, the arm, the diffusion estimate) by one verifier
    (``idpose_core.pose_hypotheses``, with ``verification``), "refine" refines the diffusion estimate by registration
    (``idpose_core.depth_fusion``); ``reachable`` and ``next_view_criterion``: where the next camera may stand and
    how it is chosen (``idpose_core.next_view``); ``min_mask_confidence``: a view cut by depth less confident than
    this that its object is apart from what was left out is never reliable and stays out of the fused cloud;
    ``cross_view_masks``: once posed, the masks get a second pass from the fused cloud (``second_mask_pass``)."""

    solver: SolverConfig
    object_distance: float = 1.0
    image_size: int = MODEL_IMAGE_SIZE
    depth_refinement: bool = True
    cloud_voxel_size: float = 0.005
    reachable: ReachableSet = ReachableSet()
    next_view_criterion: str = "bridge"
    depth_poses: str = "verify"
    verification: VerificationSettings = VerificationSettings()
    min_mask_confidence: float = MIN_MASK_CONFIDENCE
    cross_view_masks: bool = True

    def __post_init__(self) -> None:
        if self.depth_poses not in DEPTH_POSES:
            raise ValueError(f"depth_poses must be one of {', '.join(DEPTH_POSES)}, got {self.depth_poses!r}")


@dataclass(frozen=True)
class ViewReport:
    """What the pipeline read off one view: how its mask was made (``mask_method``, and ``mask_note`` when
    a more trusted source failed), its roll and polar angle from gravity and its object distance from
    depth (degrees, metres; None without gravity / depth); ``touches_border`` when the mask, in the view's
    own image, comes within ``BORDER_MARGIN_PX`` of its edge (the object is likely cut off), and
    ``reliable`` = neither touching the border, nor cut by depth with a ``mask_confidence`` (how separable the
    object is from what the cut left out; NaN for other mask methods) under the settings' minimum, nor, for a view
    other than the anchor, ambiguous; ``refinement``: what depth did to its pose (None when no depth refinement
    ran); ``mask_pass_change``: the pixels the cross-view pass added to or removed from the mask, as a share of it
    (``second_mask_pass``)."""

    mask_method: str
    mask_note: str
    roll_deg: float | None
    polar_deg: float | None
    distance: float | None
    touches_border: bool
    reliable: bool
    refinement: ViewRefinement | None = None
    mask_confidence: float = math.nan
    mask_pass_change: float = 0.0


@dataclass(frozen=True)
class PipelineResult:
    """``poses`` (N, 4, 4): camera k's real optical frame in the anchor camera's (poses[0] = identity): its metric
    6-DoF pose where depth refined it (``views[k].refinement.refined``), else the look-at model's;
    ``masks`` N bool (H_k, W_k): the object mask preprocessing chose, in view k's own image (the
    ``preprocessed`` masks are on the upright canvas of a de-rolled view);
    ``anchor_polar_deg`` and ``object_distance`` as used, with where each came from (``polar_source``:
    "gravity" or "parameter"; ``distance_source``: "depth" or "parameter"). ``runner_up_poses`` (N, 4, 4):
    each view's runner-up (``SolverResult.runner_up_poses``; the verifier's where it chose the pose) in the same
    frame, NaN for the anchor and for views without one. ``depth``: the depth refinement and the fused cloud,
    ``object``: the cloud's pose and box (both None without depth on the anchor, or with ``depth_refinement``
    off). ``next_view``: the reachable camera that best settles the views left ambiguous, or widens coverage
    (``suggest_next_view``)."""

    poses: np.ndarray
    runner_up_poses: np.ndarray
    solver_result: SolverResult
    preprocessed: PreprocessedViews
    masks: list[np.ndarray]
    views: list[ViewReport]
    anchor_polar_deg: float
    polar_source: str
    object_distance: float
    distance_source: str
    next_view: NextView
    depth: DepthRefinement | None = None
    object: ObjectFrame | None = None


def viewing_ray(view: ViewInput, mask: np.ndarray) -> np.ndarray:
    """Direction (3,) in the optical frame from the camera to the middle of the object's mask (the optical
    axis when the intrinsics are unknown)."""
    if view.intrinsics is None:
        return np.array([0.0, 0.0, 1.0])
    x, y, width, height = bounding_box(mask)
    pixel = np.array([x + (width - 1) / 2.0, y + (height - 1) / 2.0, 1.0])
    return np.linalg.solve(np.asarray(view.intrinsics, dtype=np.float64), pixel)


def touches_border(mask: np.ndarray, margin: int = BORDER_MARGIN_PX) -> bool:
    """Whether the bool mask (H, W) has a pixel within ``margin`` px of the image's edge."""
    band = margin + 1
    return bool(mask[:band].any() or mask[-band:].any() or mask[:, :band].any() or mask[:, -band:].any())


def view_report(view: ViewInput, mask: np.ndarray, method: str, note: str, roll: float,
                original_mask: np.ndarray, mask_confidence: float, min_mask_confidence: float) -> ViewReport:
    """The view's roll, gravity polar angle and depth distance, where its inputs give them, and whether its
    mask in the original image (``original_mask``) touches the border; ``reliable`` does not know the
    solver's ambiguity yet (``with_ambiguity`` adds it), only the mask's (``mask_trusted``)."""
    gravity = view.gravity_up is not None
    distance, depth_note = None, ""
    if view.depth is not None:
        try:
            distance = object_distance(view, mask)
        except DepthSegmentationError as err:
            depth_note = f"no depth distance: {err}"
    polar = math.degrees(polar_angle(view.gravity_up, viewing_ray(view, mask))) if gravity else None
    border = touches_border(original_mask)
    trusted = mask_trusted(mask_confidence, min_mask_confidence)
    notes = [note, depth_note, "" if trusted else (f"the mask is unsure: confidence {mask_confidence:.2f} < "
                                                   f"{min_mask_confidence:.2f}")]
    return ViewReport(method, "; ".join(filter(None, notes)), math.degrees(roll) if gravity else None, polar,
                      distance, touches_border=border, reliable=not border and trusted,
                      mask_confidence=mask_confidence)


def mask_trusted(confidence: float, minimum: float) -> bool:
    """Whether a view's mask can carry a reliable pose: made by another method than depth (NaN ``confidence``), or
    cut by depth at least ``minimum`` confident that the object is apart from what was left out."""
    return not confidence < minimum


def with_ambiguity(reports: Sequence[ViewReport], ambiguous: np.ndarray) -> list[ViewReport]:
    """The reports with ``reliable`` also false for the non-anchor views the solver found ambiguous
    (``ambiguous`` (N-1,), one per view after the anchor)."""
    flags = [False, *(bool(a) for a in ambiguous)]
    return [replace(report, reliable=report.reliable and not flag) for report, flag in zip(reports, flags)]


def runner_up_poses(solved: SolverResult, polar_deg: float, distance: float, rolls: Sequence[float]) -> np.ndarray:
    """The runner-ups as real-camera poses (N, 4, 4) in the anchor's frame, like the answers; NaN where none."""
    runners = np.asarray(solved.runner_up_poses, dtype=np.float64)
    found = np.isfinite(runners).all(axis=1)
    starts = np.where(found[:, None], runners, np.asarray(solved.rel_poses, dtype=np.float64))
    poses = with_roll(anchor_frame_poses(starts, math.radians(polar_deg), distance), np.array(rolls))
    poses[0] = math.nan
    poses[1:][~found] = math.nan
    return poses


def hypothesis_spheres(solved: SolverResult, polar_deg: float, distance: float) -> tuple[np.ndarray, np.ndarray]:
    """The spheres (N, 3) of every view's answer and of its runner-up (NaN rows where none, always the anchor's),
    the anchor at ``polar_deg`` (degrees), azimuth 0 and ``distance``."""
    polar = math.radians(polar_deg)
    rivals = view_spheres(solved.runner_up_poses, polar, distance)
    rivals[0] = math.nan
    return view_spheres(solved.rel_poses, polar, distance), rivals


def next_view_for(solved: SolverResult, polar_deg: float, distance: float, anchor_roll: float,
                  settings: PipelineSettings, depth: DepthRefinement | None = None) -> NextView:
    """The next camera to capture from the solver's answers and runner-ups, the anchor at ``polar_deg`` and
    ``distance`` with roll ``anchor_roll`` (rad). Where the verifier chose a view's pose (``depth``, a finite
    margin), its pose, runner-up and ambiguity replace the solver's, and its margin as a share of the ambiguity
    margin is the view's confidence: an ambiguous view is settled by a camera between it and a trusted one."""
    spheres, rivals = hypothesis_spheres(solved, polar_deg, distance)
    ambiguous = np.r_[False, np.asarray(solved.ambiguous, bool)]
    confidence = np.r_[1.0, np.asarray(solved.confidence, np.float64)]
    verified = [] if depth is None or depth.runner_up_poses is None else [
        k for k, view in enumerate(depth.views) if k and math.isfinite(view.margin)]
    if verified:
        polar = math.radians(polar_deg)
        spheres[verified] = pose_spheres(depth.poses[verified], polar, distance, anchor_roll)
        rivals[verified] = pose_spheres(depth.runner_up_poses[verified], polar, distance, anchor_roll)
        ambiguous[verified] = [depth.views[k].ambiguous for k in verified]
        confidence[verified] = np.clip([depth.views[k].margin / settings.verification.ambiguity_margin
                                        for k in verified], 0.0, 1.0)
    return suggest_next_view(spheres, rivals, ambiguous, confidence, settings.reachable,
                             settings.next_view_criterion, anchor_roll)


def depth_poses(views: Sequence[ViewInput], masks: Sequence[np.ndarray], poses: np.ndarray, runners: np.ndarray,
                confidence: np.ndarray, reports: Sequence[ViewReport],
                settings: PipelineSettings) -> DepthRefinement | None:
    """The poses of views with depth as ``settings.depth_poses`` sets them, from the diffusion's ``poses``, runner-ups
    and ``confidence`` (N,); a view whose mask is unsure (``reports``, ``mask_trusted``) stays out of the fused
    cloud (None with ``depth_refinement`` off or no object depth on the anchor)."""
    if not settings.depth_refinement:
        return None
    fuse = [mask_trusted(report.mask_confidence, settings.min_mask_confidence) for report in reports]
    if settings.depth_poses == "verify":
        return verify_with_depth(views, masks, poses, runners, settings.cloud_voxel_size, settings.verification,
                                 confidence, fuse)
    return refine_with_depth(views, masks, poses, settings.cloud_voxel_size, fuse=fuse)


def with_refinement(report: ViewReport, refinement: ViewRefinement, min_mask_confidence: float) -> ViewReport:
    """The report with what depth did to its pose; where the verifier chose the pose (a finite margin), its verdict
    replaces the solver's ambiguity in ``reliable``: the pose is reliable when its mask is whole in the image and
    trusted (``mask_trusted``), no pose of another cluster scores near it and the arm's pose, if given, agrees."""
    if not math.isfinite(refinement.margin):
        return replace(report, refinement=refinement)
    trusted = not (report.touches_border or refinement.ambiguous or refinement.object_moved) and (
        mask_trusted(report.mask_confidence, min_mask_confidence))
    return replace(report, refinement=refinement, reliable=trusted)


def second_mask_pass(views: Sequence[ViewInput], masks: Sequence[np.ndarray], reports: Sequence[ViewReport],
                     depth: DepthRefinement, settings: PipelineSettings) -> tuple[list[np.ndarray], list[ViewReport]]:
    """The masks and reports after the cross-view pass (``cross_view_masks``, with ``settings.cross_view_masks``):
    the anchor and the views depth placed unambiguously on a still object take in what the fused cloud supports,
    those also left out of the cloud lose what lies beyond it; the report's ``mask_note`` says what changed and
    ``mask_pass_change`` by how much."""
    if not settings.cross_view_masks or len(depth.cloud.points) == 0:
        return list(masks), list(reports)
    posed = [k == 0 or (r.refinement is not None and r.refinement.refined and not r.refinement.ambiguous
                        and not r.refinement.object_moved) for k, r in enumerate(reports)]
    fused = [mask_trusted(report.mask_confidence, settings.min_mask_confidence) for report in reports]
    passes = cross_view_masks(views, masks, depth.poses, depth.cloud.points, settings.cloud_voxel_size, posed, fused)
    updated = []
    for report, mask, done in zip(reports, masks, passes):
        area = max(int(np.count_nonzero(mask)), 1)
        updated.append(replace(report, mask_note="; ".join(filter(None, [report.mask_note, done.note(area)])),
                               mask_pass_change=(done.added + done.removed) / area))
    return [done.mask for done in passes], updated


def estimate_view_poses(predictor: NoisePredictor, views: Sequence[ViewInput], settings: PipelineSettings,
                        progress: Progress | None = None, cancel: threading.Event | None = None,
                        samples: SampleCount | None = None) -> PipelineResult:
    """Estimate the poses of N >= 2 views, the first one the anchor.

    Gravity (``gravity_up``) de-rolls a view, and when the anchor has it, sets the anchor's polar angle and
    every other view's with it (then searched over azimuth only); the anchor's depth sets the object
    distance. The predictor's ``solver_defaults`` fill the solver settings the caller did not choose.
    Raises ``PreprocessingError``, ``ValueError`` for fewer than 2 views, and ``Cancelled`` when ``cancel``
    is set (checked between views while preprocessing, then in the solver); ``samples`` follows the
    solver's predictor samples as they are spent.
    """
    if len(views) < 2:
        raise ValueError(f"need at least 2 views, got {len(views)}")
    upright, rolls = zip(*(upright_view(view) for view in views))
    preprocessed = preprocess_views(upright, size=settings.image_size, cancel=cancel)
    masks = [original_frame_mask(mask, view, roll) for mask, view, roll in zip(preprocessed.masks, views, rolls)]
    reports = [view_report(view, mask, method, note, roll, original, confidence, settings.min_mask_confidence)
               for view, mask, method, note, roll, original, confidence in
               zip(upright, preprocessed.masks, preprocessed.mask_methods, preprocessed.mask_notes, rolls, masks,
                   preprocessed.mask_confidences)]
    anchor = reports[0]
    solver = settings.solver
    known_polar = None
    if anchor.polar_deg is not None:
        low, high = ANCHOR_POLAR_RANGE_DEG
        solver = solver.updated(anchor_polar_deg=min(max(anchor.polar_deg, low), high))
        known_polar = [math.radians(r.polar_deg - anchor.polar_deg) if r.polar_deg is not None else math.nan
                       for r in reports[1:]]
    polar_deg = solver.anchor_polar_deg or LEVEL_POLAR_DEG
    distance = anchor.distance or settings.object_distance
    solved = estimate_poses(predictor, preprocessed.images, solver.with_recommended(predictor.solver_defaults),
                            progress=progress, cancel=cancel, known_polar=known_polar, samples=samples)
    poses = with_roll(anchor_frame_poses(solved.rel_poses, math.radians(polar_deg), distance), np.array(rolls))
    reports = with_ambiguity(reports, solved.ambiguous)
    runners = runner_up_poses(solved, polar_deg, distance, rolls)
    depth = depth_poses(views, masks, poses, runners, np.r_[1.0, solved.confidence], reports, settings)
    if depth is not None:
        poses = depth.poses
        reports = [with_refinement(report, refinement, settings.min_mask_confidence)
                   for report, refinement in zip(reports, depth.views)]
        if depth.runner_up_poses is not None:  # the verifier's runner-up where it chose the pose
            runners = depth.runner_up_poses
        masks, reports = second_mask_pass(views, masks, reports, depth, settings)
    return PipelineResult(poses=poses, runner_up_poses=runners,
                          solver_result=solved, preprocessed=preprocessed, masks=masks, views=reports,
                          anchor_polar_deg=polar_deg,
                          polar_source="gravity" if anchor.polar_deg is not None else "parameter",
                          object_distance=distance, distance_source="depth" if anchor.distance else "parameter",
                          next_view=next_view_for(solved, polar_deg, distance, rolls[0], settings, depth), depth=depth,
                          object=None if depth is None else object_frame(depth.cloud, views[0].gravity_up))


def result_details(result: PipelineResult) -> dict[str, Any]:
    """What an estimate read off its views, JSON-ready (``estimate_details``)."""
    solved = result.solver_result
    return estimate_details(result.views, result.anchor_polar_deg, result.polar_source, result.object_distance,
                            result.distance_source, solved.forward_samples, solved.backward_samples,
                            solved.stage_samples, solved.note)


def estimate_details(views: Sequence[ViewReport], anchor_polar_deg: float, polar_source: str,
                     object_distance: float, distance_source: str, forward_samples: int, backward_samples: int,
                     stage_samples: Mapping[str, Sequence[int]], solver_note: str) -> dict[str, Any]:
    """The one layout of an estimate's details, wherever they are read from (a ``PipelineResult``, or the node's
    action result): per view the mask method (and note), gravity's roll and polar angle, the depth distance,
    whether the mask touches the border, whether the pose is reliable and what depth refinement did; where the
    anchor's polar angle and distance came from; the predictor samples it took (evaluated, differentiated, and
    both per solver stage); why the solver ran another schedule than asked, if it did."""
    return {"views": [asdict(view) for view in views], "anchor_polar_deg": anchor_polar_deg,
            "polar_source": polar_source, "object_distance": object_distance, "distance_source": distance_source,
            "forward_samples": forward_samples, "backward_samples": backward_samples,
            "stage_samples": {stage: list(counts) for stage, counts in stage_samples.items()},
            "solver_note": solver_note}


def view_crops(images: torch.Tensor) -> np.ndarray:
    """Preprocessed views (N, 3, S, S) in [-1, 1] -> the images the model saw, (N, S, S, 3) RGB uint8."""
    if images.ndim != 4 or images.shape[1] != 3:
        raise ValueError(f"expected images (N, 3, S, S), got shape {tuple(images.shape)}")
    pixels = ((images.detach().float().cpu().clamp(-1, 1) + 1) * 127.5).round().to(torch.uint8)
    return np.ascontiguousarray(pixels.permute(0, 2, 3, 1).numpy())


def views_mosaic(images: torch.Tensor) -> np.ndarray:
    """Preprocessed views (N, 3, S, S) in [-1, 1] -> one RGB image (S, N*S, 3) uint8, side by side."""
    return np.concatenate(list(view_crops(images)), axis=1)
