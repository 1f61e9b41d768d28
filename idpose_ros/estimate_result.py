"""The pipeline's result as an ``EstimatePoses`` result, and back: what the node answers and a replay reads.

One definition both ways, so that an estimate replayed through the node reports exactly what an
estimate run in this process reports (``idpose_core.pipeline.result_details``).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from geometry_msgs.msg import Pose
from std_msgs.msg import Header

from idpose_core.evaluation.estimator import ViewSetEstimate
from idpose_core.pipeline import PipelineResult, ViewReport, estimate_details
from idpose_interfaces.action import EstimatePoses
from idpose_interfaces.msg import SolverStage, ViewEstimate
from msg_adapters import matrix_to_pose, pose_to_matrix, poses_to_pose_array

Result = EstimatePoses.Result


def _nan_if_none(value: float | None) -> float:
    return math.nan if value is None else float(value)


def _none_if_nan(value: float) -> float | None:
    return None if math.isnan(value) else float(value)


def no_pose() -> Pose:
    """All zeros (a quaternion of norm 0): the runner-up of a view that has none."""
    pose = Pose()
    pose.orientation.w = 0.0
    return pose


def view_estimates(result: PipelineResult, headers: Sequence[Header]) -> list[ViewEstimate]:
    """One ViewEstimate per view (the anchor first, its confidence 1), with the view's image header."""
    solved = result.solver_result
    confidence = np.concatenate([[1.0], solved.confidence])
    scores = np.concatenate([[math.nan], solved.scores])
    ambiguous = np.concatenate([[False], solved.ambiguous])
    estimates = []
    for k, (view, header) in enumerate(zip(result.views, headers)):
        runner = result.runner_up_poses[k]
        estimates.append(ViewEstimate(
            header=header, pose=matrix_to_pose(result.poses[k]), confidence=float(confidence[k]),
            score=float(scores[k]), ambiguous=bool(ambiguous[k]),
            runner_up=matrix_to_pose(runner) if np.isfinite(runner).all() else no_pose(),
            roll_deg=_nan_if_none(view.roll_deg), polar_deg=_nan_if_none(view.polar_deg),
            mask_method=view.mask_method, mask_note=view.mask_note,
            polar_source="gravity" if view.polar_deg is not None else "",
            object_distance=_nan_if_none(view.distance), touches_border=view.touches_border, reliable=view.reliable))
    return estimates


def result_message(result: PipelineResult, headers: Sequence[Header], frame_id: str, run_id: int,
                   seconds: float) -> EstimatePoses.Result:
    """A SUCCEEDED result: the poses as ``~/poses`` publishes them (the anchor's stamp, ``frame_id``) and one
    ViewEstimate per view; ``headers`` are the views' image headers, the anchor first."""
    solved = result.solver_result
    return Result(
        error_code=Result.SUCCEEDED, run_id=run_id,
        poses=poses_to_pose_array(result.poses, frame_id, headers[0].stamp),
        views=view_estimates(result, headers), object_distance=float(result.object_distance),
        distance_source=result.distance_source, anchor_polar_deg=float(result.anchor_polar_deg),
        anchor_polar_source=result.polar_source, forward_samples=solved.forward_samples,
        backward_samples=solved.backward_samples,
        stages=[SolverStage(name=name, forward_samples=forward, backward_samples=backward)
                for name, (forward, backward) in solved.stage_samples.items()],
        seconds=float(seconds))


def result_details(result: EstimatePoses.Result) -> dict[str, Any]:
    """What ``idpose_core.pipeline.result_details`` gives for the same estimate (its angles and distances
    rounded to the message's float32)."""
    views = [ViewReport(view.mask_method, view.mask_note, _none_if_nan(view.roll_deg), _none_if_nan(view.polar_deg),
                        _none_if_nan(view.object_distance), touches_border=view.touches_border,
                        reliable=view.reliable) for view in result.views]
    return estimate_details(views, result.anchor_polar_deg, result.anchor_polar_source, result.object_distance,
                            result.distance_source, result.forward_samples, result.backward_samples,
                            {stage.name: (stage.forward_samples, stage.backward_samples) for stage in result.stages})


def view_set_estimate(result: EstimatePoses.Result) -> ViewSetEstimate:
    """The evaluators' view of a SUCCEEDED result: poses, per non-anchor view score and ambiguity, details."""
    others = result.views[1:]
    return ViewSetEstimate(poses=np.stack([pose_to_matrix(pose) for pose in result.poses.poses]),
                           scores=np.array([view.score for view in others], dtype=np.float64),
                           ambiguous=np.array([view.ambiguous for view in others], dtype=bool),
                           seconds=float(result.seconds), details=result_details(result))
