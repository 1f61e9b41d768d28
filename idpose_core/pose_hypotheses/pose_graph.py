"""Several views' poses adjusted to every pair's measurement at once: a pose graph solved by least squares.

The chained choice (``chain``) places each view from one pair; every other pair that agrees with the placement
(one of its clusters within ``AGREEMENT_DEG`` of the relative pose the placement implies) is a measurement too.
``scipy.optimize.least_squares`` moves the views (the anchor fixed) to fit all of them, a robust loss keeping
one bad pair from dragging the rest; what is left per view (its largest edge residual) is the loop-closure
residual, a confidence signal.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from idpose_core.metrics import rotation_angle_deg
from idpose_core.pose_hypotheses.pair import PairRanking

AGREEMENT_DEG = 10.0  # a pair's cluster this close to the placement's relative pose measures it
ROBUST_SCALE_DEG = 3.0  # the soft-L1 loss treats residuals beyond this (and as many per cent of the size) as outliers


@dataclass(frozen=True)
class Edge:
    """A measured relative pose ``transform`` (4, 4): view ``source``'s optical frame in view ``target``'s."""

    target: int
    source: int
    transform: np.ndarray


def agreeing_edges(rankings: Mapping[tuple[int, int], PairRanking], poses: Mapping[int, np.ndarray]) -> list[Edge]:
    """For each ranked pair of placed views, its cluster nearest the placement's relative pose, if within
    ``AGREEMENT_DEG``."""
    edges = []
    for (target, source), ranking in rankings.items():
        if target not in poses or source not in poses:
            continue
        implied = np.linalg.inv(poses[target]) @ poses[source]
        nearest = min(ranking.clusters, key=lambda h: float(rotation_angle_deg(h.transform[:3, :3], implied[:3, :3])))
        if rotation_angle_deg(nearest.transform[:3, :3], implied[:3, :3]) <= AGREEMENT_DEG:
            edges.append(Edge(target, source, nearest.transform))
    return edges


def _pose(parameters: np.ndarray) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_rotvec(parameters[:3]).as_matrix()
    pose[:3, 3] = parameters[3:]
    return pose


def _residual(edge: Edge, poses: Mapping[int, np.ndarray], extent: float) -> np.ndarray:
    """(6,): the edge's rotation error (rotation vector, rad) and translation error (shares of ``extent``)."""
    error = np.linalg.inv(edge.transform) @ np.linalg.inv(poses[edge.target]) @ poses[edge.source]
    return np.concatenate([Rotation.from_matrix(error[:3, :3]).as_rotvec(), error[:3, 3] / extent])


def optimise(poses: Mapping[int, np.ndarray], edges: list[Edge], extent: float) -> tuple[dict[int, np.ndarray],
                                                                                        dict[int, float]]:
    """The placed ``poses`` (view -> (4, 4) in the anchor's frame, the anchor 0 fixed) fitted to the ``edges``,
    and per view the largest rotation residual (deg) of its edges after the fit (0 for a view in no edge)."""
    free = sorted(k for k in poses if k != 0)
    if not free or not edges:
        return dict(poses), {k: 0.0 for k in free}
    start = np.concatenate([np.r_[Rotation.from_matrix(poses[k][:3, :3]).as_rotvec(), poses[k][:3, 3]]
                            for k in free])

    def placed(parameters: np.ndarray) -> dict[int, np.ndarray]:
        return {0: np.eye(4), **{k: _pose(parameters[6 * i:6 * i + 6]) for i, k in enumerate(free)}}

    def residuals(parameters: np.ndarray) -> np.ndarray:
        current = placed(parameters)
        return np.concatenate([_residual(edge, current, extent) for edge in edges])

    solved = least_squares(residuals, start, loss="soft_l1", f_scale=np.radians(ROBUST_SCALE_DEG))
    fitted = placed(solved.x)
    loops = {k: max((float(np.degrees(np.linalg.norm(_residual(edge, fitted, extent)[:3]))) for edge in edges
                     if k in (edge.target, edge.source)), default=0.0) for k in free}
    return fitted, loops
