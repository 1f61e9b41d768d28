"""A relative pose proposed for a view, by which source, and what the verifier made of it."""
from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from idpose_core.metrics import rotation_angle_deg

FAR_STAGES = (0.1, 0.05, 0.025)  # shares of the object's extent: local registration's match distances, stage by stage
NEAR_STAGES = (0.025,)  # a polish: only near matches, for a hypothesis already close


class Source(enum.StrEnum):
    """Where a pose hypothesis came from."""

    DIFFUSION = "diffusion"  # the model's answer and runner-up, the only source without depth
    REGISTRATION = "registration"  # global registration of the two views' object clouds
    GRAVITY = "gravity"  # both views know gravity: the yaw about the vertical searched exhaustively
    ARM = "arm"  # both cameras' poses in a fixed frame (the arm's kinematics)


@dataclass(frozen=True)
class Hypothesis:
    """``transform`` (4, 4): the source view's optical frame in the target view's; ``source`` proposed it;
    ``stages``: the local registration it gets before it is scored (shares of the object's extent; empty: none)."""

    transform: np.ndarray
    source: Source
    stages: tuple[float, ...] = FAR_STAGES


@dataclass(frozen=True)
class ScoredHypothesis:
    """A hypothesis as the verifier judged it: its ``transform`` (4, 4) after local registration, its ``source``,
    the verifier's ``score`` (higher is better) and the part of it the object alone gave (``object_score``: what
    tells a moved object, where the surroundings stood still)."""

    transform: np.ndarray
    source: Source
    score: float
    object_score: float


def same_pose(first: np.ndarray, second: np.ndarray, rotation_deg: float, translation: float) -> bool:
    """Whether two transforms (4, 4) are within ``rotation_deg`` and ``translation`` (m) of each other."""
    return (float(rotation_angle_deg(first[:3, :3], second[:3, :3])) <= rotation_deg
            and float(np.linalg.norm(first[:3, 3] - second[:3, 3])) <= translation)
