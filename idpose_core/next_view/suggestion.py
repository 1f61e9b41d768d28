"""``suggest_next_view``: score the reachable cameras against the estimate's hypotheses and pick one.

Each ambiguous view k has two hypotheses, its answer a_k and its runner-up b_k. A new camera c settles them when the
model can link c to view k and to the views already trusted through short baselines under one hypothesis, while
the other puts view k far from c (criterion ``bridge``), or, more simply, when c is much nearer one hypothesis than
the other (``contrast``). With nothing ambiguous, the camera farthest from every view widens the coverage. Angles
are between viewing directions from the object centre, in radians; spheres follow :mod:`idpose_core.spherical`.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from idpose_core.cameras import apply_relative, first_camera_frame_poses, opengl_to_optical, spherical_to_c2w
from idpose_core.gravity import rz, with_roll
from idpose_core.next_view.reachable import ReachableSet
from idpose_core.spherical import cartesian_to_spherical, spherical_to_cartesian

# Among candidates scoring the same, prefer the one nearest the trusted views, by this much per radian: a camera
# whose own pose is easy to find is worth more.
NEARNESS_TIE_BREAK = 1e-3


@dataclass(frozen=True)
class NextView:
    """The suggested camera: ``sphere`` (3,) = (polar, azimuth, radius) in the estimate's world (anchor at azimuth
    0), ``pose`` (4, 4) its optical frame in the anchor camera's optical frame, upright (no roll about gravity),
    looking at the object centre; ``gain`` in [0, 1] (how well it separates the hypotheses, or how much new
    coverage it adds), ``reason`` in words, ``view`` the ambiguous view it settles (None for coverage)."""

    sphere: np.ndarray
    pose: np.ndarray
    gain: float
    reason: str
    view: int | None


def view_spheres(rel_poses: np.ndarray, anchor_polar: float, distance: float) -> np.ndarray:
    """Absolute spheres (N, 3) of the anchor (polar ``anchor_polar``, azimuth 0, ``distance`` m) and of the views
    at the solver's relative poses ``rel_poses`` (N-1, 3); a NaN row stays NaN (a view without a runner-up)."""
    anchor = np.array([anchor_polar, 0.0, distance], dtype=np.float64)
    rel = np.asarray(rel_poses, dtype=np.float64).reshape(-1, 3)
    found = np.isfinite(rel).all(axis=1)
    spheres = np.full((len(rel) + 1, 3), math.nan)
    spheres[0] = anchor
    if found.any():
        spheres[1:][found] = apply_relative(anchor, rel[found])
    return spheres


def pose_spheres(poses: np.ndarray, anchor_polar: float, distance: float, anchor_roll: float) -> np.ndarray:
    """Spheres (N, 3) of the cameras whose optical frames ``poses`` (N, 4, 4) are given in the real anchor's frame
    (the upright anchor turned by ``anchor_roll`` rad about its axis), the anchor at (``anchor_polar``, 0,
    ``distance``) looking at the object centre; a NaN pose gives a NaN row. The inverse of placing spheres with
    ``first_camera_frame_poses`` and ``with_roll``."""
    world_from_anchor = opengl_to_optical(spherical_to_c2w(np.array([anchor_polar, 0.0, distance])))
    turn = np.eye(4)
    turn[:3, :3] = rz(anchor_roll)
    return cartesian_to_spherical((world_from_anchor @ turn @ np.asarray(poses, np.float64))[:, :3, 3])


def angles_between(spheres_a: np.ndarray, spheres_b: np.ndarray) -> np.ndarray:
    """Angles (A, B) between the viewing directions of spheres (A, 3) and (B, 3) from the object centre."""
    def directions(spheres: np.ndarray) -> np.ndarray:
        unit = np.asarray(spheres, dtype=np.float64).copy()
        unit[:, 2] = 1.0
        return spherical_to_cartesian(unit)

    return np.arccos(np.clip(directions(spheres_a) @ directions(spheres_b).T, -1.0, 1.0))


def bridge_score(to_answer: np.ndarray, to_rival: np.ndarray, to_trusted: np.ndarray, apart: float) -> np.ndarray:
    """Per candidate, in [0, 1]: under one hypothesis, how much farther the other puts view k than the longer link
    of the chain trusted views -> candidate -> view k (``to_*``: angles (M,) from each candidate)."""
    nearest = to_trusted.min(axis=1)
    through_answer = to_rival - np.maximum(nearest, to_answer)
    through_rival = to_answer - np.maximum(nearest, to_rival)
    return np.clip(np.maximum(through_answer, through_rival), 0.0, None) / max(apart, 1e-9)


def contrast_score(to_answer: np.ndarray, to_rival: np.ndarray, to_trusted: np.ndarray, apart: float) -> np.ndarray:
    """Per candidate, in [0, 1]: how much nearer one hypothesis is than the other, as a share of their distance."""
    return np.abs(to_answer - to_rival) / max(apart, 1e-9)


CRITERIA: dict[str, Callable[..., np.ndarray]] = {"bridge": bridge_score, "contrast": contrast_score}


def suggest_next_view(spheres: np.ndarray, rivals: np.ndarray, ambiguous: np.ndarray, confidence: np.ndarray,
                      reachable: ReachableSet, criterion: str = "bridge", anchor_roll: float = 0.0) -> NextView:
    """The reachable camera that best settles the ambiguous views, or widens coverage when none is ambiguous.

    ``spheres`` (N, 3): every view's estimated sphere, the anchor first (``view_spheres``); ``rivals`` (N, 3): each
    view's runner-up sphere (NaN rows where none, always for the anchor); ``ambiguous`` and ``confidence`` (N,),
    the anchor's False and 1; ``anchor_roll`` (rad) the anchor camera's roll, so the pose is in its real frame.
    The candidates stand at the anchor's distance clipped to the reachable range. Raises ValueError for an unknown
    criterion or mismatched shapes.
    """
    if criterion not in CRITERIA:
        raise ValueError(f"unknown next-view criterion {criterion!r}; choose one of {sorted(CRITERIA)}")
    spheres, rivals = np.asarray(spheres, np.float64), np.asarray(rivals, np.float64)
    ambiguous, confidence = np.asarray(ambiguous, bool), np.asarray(confidence, np.float64)
    if not (spheres.shape == rivals.shape == (len(ambiguous), 3) and confidence.shape == ambiguous.shape):
        raise ValueError(f"spheres {spheres.shape}, rivals {rivals.shape}, ambiguous {ambiguous.shape} and "
                         f"confidence {confidence.shape} must describe the same N views")
    candidates = reachable.candidates(float(spheres[0, 2]))
    to_views = angles_between(candidates, spheres)
    unsettled = [k for k in np.flatnonzero(ambiguous) if np.isfinite(rivals[k]).all()]
    if unsettled:
        trusted = np.ones(len(spheres), bool)
        trusted[unsettled] = False
        to_rivals = angles_between(candidates, rivals[unsettled])
        apart = np.diag(angles_between(spheres[unsettled], rivals[unsettled]))
        per_view = np.stack([(1.0 - confidence[k]) * CRITERIA[criterion](
            to_views[:, k], to_rivals[:, i], to_views[:, trusted], apart[i]) for i, k in enumerate(unsettled)], axis=1)
        score = per_view.mean(axis=1)
        best = int(np.argmax(score - NEARNESS_TIE_BREAK * to_views[:, trusted].min(axis=1)))
        view = unsettled[int(np.argmax(per_view[best]))]
        apart_deg = math.degrees(apart[unsettled.index(view)])
        reason = f"ambiguous view {view}: its answer and its runner-up are {apart_deg:.0f} deg apart ({criterion})"
        gain = float(score[best])
    else:
        coverage = to_views.min(axis=1)
        best, view = int(np.argmax(coverage)), None
        reason = f"coverage: nothing is ambiguous; {math.degrees(coverage[best]):.0f} deg from the nearest view"
        gain = float(coverage[best] / math.pi)
    upright = first_camera_frame_poses(np.stack([spheres[0], candidates[best]]))
    pose = with_roll(upright, np.array([anchor_roll, 0.0]))[1]
    return NextView(sphere=candidates[best], pose=pose, gain=gain, reason=reason, view=view)
