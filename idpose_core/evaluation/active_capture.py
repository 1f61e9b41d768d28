"""Active capture in a closed loop on a rendered object: estimate, move the camera where a policy says, capture,
estimate again, up to a number of views; each step's per-view rotation errors against the rendered truth.

It measures whether the node's suggested next view (``PipelineResult.next_view``) settles an estimate better than
other ways to pick the next camera. Every view carries exact gravity (a robot arm knows which way is up), so the
estimate's world is the true one turned about the vertical by the anchor's azimuth, and a chosen camera maps to a
true camera by adding that azimuth back.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from idpose_core.cameras import first_camera_frame_poses, opengl_to_optical, spherical_to_c2w
from idpose_core.gravity import up_from_orientation
from idpose_core.metrics import rotation_angle_deg
from idpose_core.next_view import ReachableSet, suggest_next_view
from idpose_core.next_view.suggestion import angles_between
from idpose_core.noise_predictor import NoisePredictor
from idpose_core.pipeline import (
    PipelineResult,
    PipelineSettings,
    estimate_view_poses,
    hypothesis_spheres,
    next_view_for,
)
from idpose_core.synthetic.scenes import Light, ObjectSpec, SceneRenderer
from idpose_core.view_input import ViewInput

POLICIES = ("suggested", "contrast", "coverage", "largest_gap", "random")
"""How the next camera is picked: the suggestion with its default criterion (bridge) or with ``contrast``; the
reachable camera farthest from every estimated view, ignoring ambiguity (``coverage``); the middle of the widest
azimuth gap between the estimated views at the anchor's polar angle (``largest_gap``); a reachable camera at
random (``random``)."""
MIN_START_SEPARATION_DEG = 30.0  # the second view of a start is at least this far from the anchor


@dataclass(frozen=True)
class CaptureStart:
    """Where a loop begins: the object, its light, and the true spheres (polar, azimuth, radius; radians, metres)
    of the anchor camera and of the second view."""

    spec: ObjectSpec
    light: Light
    anchor: np.ndarray
    second: np.ndarray


@dataclass(frozen=True)
class LoopStep:
    """One estimate of a loop on ``views`` views: the rotation error (degrees) and the ambiguity flag of each
    non-anchor view (``views - 1``,), the predictor samples it took, the estimated spheres of every view and of
    its runner-up (``views``, 3; the estimate's world, NaN rows where none), and the true sphere of the camera the
    policy picked next (None after the last estimate)."""

    views: int
    rotation_errors_deg: np.ndarray
    ambiguous: np.ndarray
    forward_samples: int
    spheres: np.ndarray
    rivals: np.ndarray
    next_camera: np.ndarray | None


def random_starts(objects: list[ObjectSpec], lights: list[Light], count: int, reachable: ReachableSet,
                  distance: float, rng: np.random.Generator) -> list[CaptureStart]:
    """``count`` starts cycling through ``objects`` (and ``lights``): the anchor and the second view at random
    reachable cameras (polar and azimuth drawn uniformly in the reachable ranges), at least
    ``MIN_START_SEPARATION_DEG`` apart."""
    starts = []
    for k in range(count):
        anchor = np.array([math.radians(rng.uniform(*reachable.polar_deg)), rng.uniform(-math.pi, math.pi), distance])
        while True:
            offset = np.radians([rng.uniform(*reachable.polar_deg), rng.uniform(*reachable.azimuth_deg)])
            second = np.array([offset[0], anchor[1] + offset[1], distance])
            if math.degrees(angles_between(anchor[None], second[None])[0, 0]) >= MIN_START_SEPARATION_DEG:
                break
        starts.append(CaptureStart(objects[k % len(objects)], lights[k % len(lights)], anchor, second))
    return starts


def rendered_view(renderer: SceneRenderer, sphere: np.ndarray, light: Light) -> ViewInput:
    """The object seen from the true ``sphere``, upright, with its mask as alpha and its exact gravity."""
    rgb, mask = renderer.render(sphere[0], sphere[1], sphere[2], light=light)
    world_from_optical = opengl_to_optical(spherical_to_c2w(np.asarray(sphere, dtype=np.float64)))
    return ViewInput(rgb=rgb, alpha=(mask * 255).astype(np.uint8),
                     gravity_up=up_from_orientation(world_from_optical[:3, :3]))


def next_camera(policy: str, result: PipelineResult, settings: PipelineSettings, rng: np.random.Generator
                ) -> np.ndarray:
    """The sphere (estimate's world: the anchor at azimuth 0) of the camera ``policy`` picks after ``result``.
    Raises ValueError for an unknown policy."""
    solved, distance = result.solver_result, result.object_distance
    spheres, _ = hypothesis_spheres(solved, result.anchor_polar_deg, distance)
    if policy == "suggested":
        return result.next_view.sphere
    if policy == "contrast":
        contrast = replace(settings, next_view_criterion="contrast")
        return next_view_for(solved, result.anchor_polar_deg, distance, 0.0, contrast).sphere
    if policy == "coverage":
        none = np.zeros(len(spheres), bool)
        return suggest_next_view(spheres, np.full_like(spheres, math.nan), none, np.ones(len(spheres)),
                                 settings.reachable).sphere
    if policy == "largest_gap":
        return largest_gap_camera(spheres, settings.reachable)
    if policy == "random":
        candidates = settings.reachable.candidates(distance)
        return candidates[rng.integers(len(candidates))]
    raise ValueError(f"unknown capture policy {policy!r}; choose one of {', '.join(POLICIES)}")


def largest_gap_camera(spheres: np.ndarray, reachable: ReachableSet) -> np.ndarray:
    """The reachable camera nearest the middle of the widest azimuth gap between ``spheres`` (N, 3), at the first
    (the anchor's) polar angle."""
    azimuths = np.sort(np.mod(spheres[:, 1], 2.0 * math.pi))
    gaps = np.diff(np.r_[azimuths, azimuths[0] + 2.0 * math.pi])
    widest = int(np.argmax(gaps))
    target = np.array([[spheres[0, 0], azimuths[widest] + gaps[widest] / 2.0, spheres[0, 2]]])
    candidates = reachable.candidates(float(spheres[0, 2]))
    return candidates[int(np.argmin(angles_between(candidates, target)[:, 0]))]


def run_loop(predictor: NoisePredictor, start: CaptureStart, policy: str, settings: PipelineSettings,
             max_views: int, image_size: int, rng: np.random.Generator) -> list[LoopStep]:
    """Estimate on the start's two views, then add the camera ``policy`` picks and estimate again, until
    ``max_views`` views; one ``LoopStep`` per estimate. ``settings.object_distance`` should be the start's."""
    spheres = [start.anchor, start.second]
    steps = []
    with SceneRenderer(start.spec, image_size=image_size) as renderer:
        views = [rendered_view(renderer, sphere, start.light) for sphere in spheres]
        while True:
            result = estimate_view_poses(predictor, views, settings)
            truth = first_camera_frame_poses(np.stack(spheres))
            errors = rotation_angle_deg(result.poses[1:, :3, :3], truth[1:, :3, :3])
            ambiguous = np.asarray(result.solver_result.ambiguous, bool)
            done = len(views) >= max_views
            chosen = None
            if not done:
                chosen = next_camera(policy, result, settings, rng).copy()
                chosen[1] += start.anchor[1]  # the estimate's world -> the true one (exact gravity: same polar)
            steps.append(LoopStep(len(views), errors, ambiguous, int(result.solver_result.forward_samples),
                                  *hypothesis_spheres(result.solver_result, result.anchor_polar_deg,
                                                      result.object_distance), chosen))
            if done:
                return steps
            spheres.append(chosen)
            views.append(rendered_view(renderer, chosen, start.light))
