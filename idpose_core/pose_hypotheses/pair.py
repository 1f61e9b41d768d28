"""Two views' hypotheses refined by local registration, scored by the verifier, clustered and ranked."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import small_gicp

from idpose_core.metrics import rotation_angle_deg
from idpose_core.pose_hypotheses.hypothesis import Hypothesis, ScoredHypothesis, Source, same_pose
from idpose_core.pose_hypotheses.verifier import ViewEvidence, verify

NEIGHBOURS = 10  # points for each GICP covariance
ITERATIONS = 30  # per stage
CLUSTER_DEG = 10.0  # hypotheses this close in rotation (and ``CLUSTER_SHARE`` of the extent in translation) are one
CLUSTER_SHARE = 0.25
POLISHED = 8  # the best clusters that get a polish on the object and its surroundings after scoring
CONTEXT_STAGES = (0.05, 0.025)  # that polish's match distances (shares of the object's extent)
# The arm's pose is a measurement, good to a degree or two: a pose near it (within ``ARM_TOLERANCE_DEG`` and
# ``CLUSTER_SHARE`` of the extent), whatever its source, wins unless a pose far from it scores ``ARM_PRIOR`` better
ARM_PRIOR = 0.5
ARM_TOLERANCE_DEG = 5.0
# The diffusion answer is as good as the model: a pose within this (deg) of it gets the trust the settings give the
# model, times the solver's confidence in it
DIFFUSION_TOLERANCE_DEG = 15.0


@dataclass(frozen=True)
class PairClouds:
    """Two views' object points prepared once for many registrations: thinned to ``voxel`` (m), with the target's
    tree, and the ``extent`` (m) that scales match distances."""

    source: small_gicp.PointCloud
    target: small_gicp.PointCloud
    target_tree: small_gicp.KdTree
    voxel: float
    extent: float


@dataclass(frozen=True)
class Priors:
    """What a pair's poses get before the verifier speaks: ``ARM_PRIOR`` near the ``arm``'s measured pose (4, 4),
    and ``diffusion_weight`` within ``DIFFUSION_TOLERANCE_DEG`` of the ``diffusion`` answer (4, 4) (None: none)."""

    arm: np.ndarray | None = None
    diffusion: np.ndarray | None = None
    diffusion_weight: float = 0.0

    def near_arm(self, transform: np.ndarray, extent: float) -> bool:
        """Whether ``transform`` (4, 4) lies within the arm's error of the pose it measured."""
        return self.arm is not None and same_pose(transform, self.arm, ARM_TOLERANCE_DEG, CLUSTER_SHARE * extent)

    def of(self, transform: np.ndarray, extent: float) -> float:
        """The prior of ``transform`` (4, 4) in a pair whose object is ``extent`` (m) across."""
        near_diffusion = (self.diffusion is not None and self.diffusion_weight > 0.0 and float(rotation_angle_deg(
            transform[:3, :3], self.diffusion[:3, :3])) <= DIFFUSION_TOLERANCE_DEG)
        return (ARM_PRIOR if self.near_arm(transform, extent) else 0.0) + (
            self.diffusion_weight if near_diffusion else 0.0)


@dataclass(frozen=True)
class PairRanking:
    """A pair's hypotheses, one per cluster, best first (at least one), every hypothesis scored (``scored``), and
    the ``priors`` they were scored with."""

    clusters: list[ScoredHypothesis]
    scored: list[ScoredHypothesis]
    priors: Priors = Priors()

    @property
    def best(self) -> ScoredHypothesis:
        return self.clusters[0]

    @property
    def runner_up(self) -> ScoredHypothesis | None:
        """The best hypothesis of another cluster, None when every hypothesis fell in one."""
        return self.clusters[1] if len(self.clusters) > 1 else None

    @property
    def margin(self) -> float:
        """The best score's lead over the runner-up (the best score itself when there is none)."""
        return self.best.score - (self.runner_up.score if self.runner_up is not None else 0.0)


def prepare_pair(source: np.ndarray, target: np.ndarray, voxel: float, extent: float) -> PairClouds:
    """``source`` and ``target`` object points (M, 3), (K, 3) thinned and given covariances for GICP."""
    source_cloud, _ = small_gicp.preprocess_points(source, voxel, num_neighbors=NEIGHBOURS)
    target_cloud, target_tree = small_gicp.preprocess_points(target, voxel, num_neighbors=NEIGHBOURS)
    return PairClouds(source_cloud, target_cloud, target_tree, voxel, extent)


def refine(pair: PairClouds, initial: np.ndarray, stages: Sequence[float]) -> np.ndarray:
    """GICP from ``initial`` (4, 4), matching points up to each of ``stages`` shares of the extent in turn."""
    transform = np.asarray(initial, dtype=np.float64)
    for share in stages:
        result = small_gicp.align(pair.target, pair.source, pair.target_tree, init_T_target_source=transform,
                                  registration_type="GICP", max_correspondence_distance=share * pair.extent,
                                  max_iterations=ITERATIONS)
        transform = np.asarray(result.T_target_source)
    return transform


def clusters_of(scored: Sequence[ScoredHypothesis], extent: float) -> list[ScoredHypothesis]:
    """The best hypothesis of each cluster (within ``CLUSTER_DEG`` and ``CLUSTER_SHARE`` of the extent of a better
    one), best first."""
    leaders: list[ScoredHypothesis] = []
    for candidate in sorted(scored, key=lambda h: -h.score):
        if not any(same_pose(candidate.transform, leader.transform, CLUSTER_DEG, CLUSTER_SHARE * extent)
                   for leader in leaders):
            leaders.append(candidate)
    return leaders


def rank_pair(target: ViewEvidence, source: ViewEvidence, pair: PairClouds, hypotheses: Sequence[Hypothesis],
              priors: Priors = Priors()) -> PairRanking:
    """Each of the ``hypotheses`` (source view in target view) registered locally as it asks, scored by the
    verifier on both views (with their ``priors``), ranked per cluster; the
    ``POLISHED`` best clusters are polished by registering the object with its surroundings (the table patch and
    what stands near fix a slide the object alone leaves free), and keep the polish where it scores higher. Needs
    at least one hypothesis."""
    def scored(transform: np.ndarray, origin: Source) -> ScoredHypothesis:
        verdict = verify(target, source, transform, pair.voxel)
        return ScoredHypothesis(transform, origin, verdict.score + priors.of(transform, pair.extent),
                                verdict.object.score)

    found = [scored(refine(pair, h.transform, h.stages), h.source) for h in hypotheses]
    clusters = clusters_of(found, pair.extent)
    surroundings = prepare_pair(source.context.points, target.context.points, pair.voxel, pair.extent)
    polished = [scored(refine(surroundings, h.transform, CONTEXT_STAGES), h.source) for h in clusters[:POLISHED]]
    better = [p if p.score > h.score else h for p, h in zip(polished, clusters[:POLISHED])]
    return PairRanking(clusters_of(better + clusters[POLISHED:], pair.extent), found + polished, priors)
