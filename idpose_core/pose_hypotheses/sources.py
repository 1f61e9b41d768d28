"""Sources of relative-pose hypotheses between two views: each proposes several, the verifier chooses.

All transforms are (4, 4), the source view's optical frame in the target view's.
"""
from __future__ import annotations

import math

import kiss_matcher
import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from idpose_core.gravity import level_from_optical, rz
from idpose_core.pose_hypotheses.hypothesis import FAR_STAGES, NEAR_STAGES, Hypothesis, Source
from idpose_core.segmentation import Plane

YAW_STEPS = 72  # gravity: yaw candidates about the vertical (every 5 deg)
SLIDE_ROUNDS = 8  # gravity: rounds of the sideways slide that lays the object clouds together
SLIDE_REACH = 0.3  # of the object's extent: how far apart points are matched in the first slide round
SLIDE_LIMIT = 0.5  # of the object's extent: a slide that goes farther is undone (it ran off the object)
SLIDE_POINTS = 800  # source points a slide matches (a fixed sample: large objects cost no more)
# registration: starts spread over the rotation group (the octahedral group's 24 turns) beside the feature match
START_GROUP = "O"
FEATURE_VOXEL_SHARE = 1.0 / 25.0  # of the object's extent: the voxel KISS-Matcher's features are computed on
# KISS-Matcher refuses voxels under a few centimetres (it is made for lidar scans): the clouds are scaled to this
# extent (m) for it and its translation scaled back
FEATURE_EXTENT = 10.0


def centred(rotation: np.ndarray, source_centre: np.ndarray, target_centre: np.ndarray) -> np.ndarray:
    """The transform (4, 4) with ``rotation`` (3, 3) that takes ``source_centre`` (3,) onto ``target_centre``."""
    transform = np.eye(4)
    transform[:3, :3] = rotation
    transform[:3, 3] = target_centre - rotation @ source_centre
    return transform


def feature_match(source: np.ndarray, target: np.ndarray, extent: float) -> Hypothesis | None:
    """KISS-Matcher's global registration (Faster-PFH features, graduated non-convexity) of ``source`` (M, 3)
    onto ``target`` (K, 3); None when it finds no valid solution."""
    scale = FEATURE_EXTENT / extent
    matcher = kiss_matcher.KISSMatcher(kiss_matcher.KISSMatcherConfig(voxel_size=FEATURE_VOXEL_SHARE * FEATURE_EXTENT))
    solution = matcher.estimate(np.asarray(source * scale, np.float32), np.asarray(target * scale, np.float32))
    if not solution.valid:
        return None
    transform = np.eye(4)
    transform[:3, :3] = np.asarray(solution.rotation, dtype=np.float64)
    transform[:3, 3] = np.asarray(solution.translation, dtype=np.float64).ravel() / scale
    return Hypothesis(transform, Source.REGISTRATION)


def registration_hypotheses(source: np.ndarray, target: np.ndarray, extent: float) -> list[Hypothesis]:
    """Global registration's proposals for ``source`` (M, 3) onto ``target`` (K, 3) object points: KISS-Matcher's
    feature match, and the clouds' means laid together under each turn of ``START_GROUP`` (local registration from
    there searches where features find too few matches)."""
    source_mean, target_mean = source.mean(axis=0), target.mean(axis=0)
    starts = [Hypothesis(centred(turn, source_mean, target_mean), Source.REGISTRATION)
              for turn in Rotation.create_group(START_GROUP).as_matrix()]
    matched = feature_match(source, target, extent)
    return ([matched] if matched is not None else []) + starts


def slide(source: np.ndarray, target_tree: cKDTree, transform: np.ndarray, extent: float,
          normal: np.ndarray | None) -> np.ndarray:
    """``transform`` (4, 4) moved, not turned, so that the placed ``source`` points (M, 3) meet the target's (the
    median offset to each point's nearest target point, the reach narrowing round by round), along the plane of
    ``normal`` (3,) when given; the transform unmoved when the slide runs beyond ``SLIDE_LIMIT``."""
    moved = transform.copy()
    for reach in np.linspace(SLIDE_REACH, SLIDE_REACH / 4, SLIDE_ROUNDS) * extent:
        placed = source @ moved[:3, :3].T + moved[:3, 3]
        distance, index = target_tree.query(placed, distance_upper_bound=reach)
        matched = np.isfinite(distance)
        if matched.sum() < 10:
            break
        step = np.median(target_tree.data[index[matched]] - placed[matched], axis=0)
        if normal is not None:
            step -= normal * (step @ normal)
        moved[:3, 3] += step
    if np.linalg.norm(moved[:3, 3] - transform[:3, 3]) > SLIDE_LIMIT * extent:
        return transform
    return moved


def gravity_hypotheses(source: np.ndarray, target: np.ndarray, source_up: np.ndarray, target_up: np.ndarray,
                       source_centre: np.ndarray, target_centre: np.ndarray, extent: float,
                       planes: tuple[Plane, Plane] | None = None, steps: int = YAW_STEPS) -> list[Hypothesis]:
    """With world up known in both views (``source_up``, ``target_up``: (3,) in each optical frame) only the yaw
    about the vertical and a translation are free. For each of ``steps`` yaws: the objects' centres (3,) laid
    together, the camera's height over the support when both views' ``planes`` (source, target) give it, then a
    sideways slide of the object points (M, 3), (K, 3) onto each other. Only a polish follows (``NEAR_STAGES``):
    far matches would undo the search."""
    source_level, target_level = level_from_optical(source_up), level_from_optical(target_up)
    tree = cKDTree(target)
    if len(source) > SLIDE_POINTS:
        source = source[np.random.default_rng(0).choice(len(source), SLIDE_POINTS, replace=False)]
    hypotheses = []
    for k in range(steps):
        transform = centred(target_level.T @ rz(2 * math.pi * k / steps) @ source_level, source_centre, target_centre)
        normal = None
        if planes is not None:
            source_plane, target_plane = planes
            normal = target_plane.normal
            transform[:3, 3] += normal * (source_plane.offset - target_plane.height(transform[:3, 3]))
        hypotheses.append(Hypothesis(slide(source, tree, transform, extent, normal), Source.GRAVITY, NEAR_STAGES))
    return hypotheses


def arm_pose(source_in_fixed: np.ndarray, target_in_fixed: np.ndarray) -> np.ndarray:
    """The relative pose (4, 4) the arm's kinematics measure: both cameras' optical frames (4, 4) in one fixed
    frame."""
    return np.linalg.inv(np.asarray(target_in_fixed, np.float64)) @ np.asarray(source_in_fixed, np.float64)


def arm_hypotheses(measured: np.ndarray) -> list[Hypothesis]:
    """The arm's ``measured`` relative pose (4, 4) as it is, and registered locally from there. A degree off in a
    camera's orientation moves the object about a centimetre at half a metre: too far for a polish of near matches
    alone. Noisy depth can slide a registration off; the measured pose keeps the verifier from losing the arm's."""
    return [Hypothesis(measured, Source.ARM, ()), Hypothesis(measured, Source.ARM, FAR_STAGES)]
