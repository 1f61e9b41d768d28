"""The pipeline's result as an ``EstimatePoses`` result, and back: what the node answers and a replay reads.

One definition both ways, so that an estimate replayed through the node reports exactly what an
estimate run in this process reports (``idpose_core.pipeline.result_details``).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from geometry_msgs.msg import Pose, PoseStamped, Vector3
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Header

from idpose_core.depth_fusion import ObjectCloud, ViewRefinement
from idpose_core.evaluation.estimator import ViewSetEstimate
from idpose_core.pipeline import PipelineResult, ViewReport, estimate_details
from idpose_interfaces.action import EstimatePoses
from idpose_interfaces.msg import SolverStage, ViewEstimate
from msg_adapters import cloud_to_points, matrix_to_pose, points_to_cloud, pose_to_matrix, poses_to_pose_array

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


def depth_fields(refinement: ViewRefinement | None) -> dict[str, Any]:
    """A ViewEstimate's depth fields: what depth did to the view's pose (empty note and NaNs when no refinement
    ran), as Python bools and floats (rclpy's C conversion aborts the process on a numpy bool)."""
    if refinement is None:
        return {"depth_refined": False, "depth_note": "", "depth_fitness": math.nan, "depth_inlier_rmse": math.nan,
                "depth_rotation_change_deg": 0.0, "depth_translation_change": 0.0, "pose_source": "diffusion",
                "verifier_margin": math.nan, "object_moved": False, "loop_residual_deg": math.nan}
    return {"depth_refined": bool(refinement.refined), "depth_note": refinement.note,
            "depth_fitness": float(refinement.fitness), "depth_inlier_rmse": float(refinement.inlier_rmse),
            "depth_rotation_change_deg": float(refinement.rotation_change_deg),
            "depth_translation_change": float(refinement.translation_change), "pose_source": refinement.source,
            "verifier_margin": float(refinement.margin), "object_moved": bool(refinement.object_moved),
            "loop_residual_deg": float(refinement.loop_residual_deg)}


def refinement_of(view: ViewEstimate) -> ViewRefinement | None:
    """The ViewRefinement a ViewEstimate's depth fields carry (None when no refinement ran: an empty note)."""
    if not view.depth_note and not view.depth_refined:
        return None
    margin = float(view.verifier_margin)
    return ViewRefinement(view.depth_refined, view.depth_note, float(view.depth_fitness),
                          float(view.depth_inlier_rmse), float(view.depth_rotation_change_deg),
                          float(view.depth_translation_change), view.pose_source or "diffusion", margin,
                          bool(view.ambiguous) if math.isfinite(margin) else False, view.object_moved,
                          float(view.loop_residual_deg))


def view_ambiguous(view: ViewReport, solver_ambiguous: bool) -> bool:
    """The verifier's ambiguity where it chose the view's pose (a finite margin), else the solver's."""
    refinement = view.refinement
    if refinement is not None and math.isfinite(refinement.margin):
        return bool(refinement.ambiguous)
    return solver_ambiguous


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
            score=float(scores[k]), ambiguous=view_ambiguous(view, bool(ambiguous[k])),
            runner_up=matrix_to_pose(runner) if np.isfinite(runner).all() else no_pose(),
            roll_deg=_nan_if_none(view.roll_deg), polar_deg=_nan_if_none(view.polar_deg),
            mask_method=view.mask_method, mask_note=view.mask_note, mask_confidence=float(view.mask_confidence),
            mask_pass_change=float(view.mask_pass_change),
            polar_source="gravity" if view.polar_deg is not None else "",
            object_distance=_nan_if_none(view.distance), touches_border=bool(view.touches_border),
            reliable=bool(view.reliable),
            **depth_fields(view.refinement)))
    return estimates


def object_messages(result: PipelineResult, frame_id: str, stamp) -> tuple[PointCloud2, PoseStamped, Vector3, str]:
    """The object's fused cloud, box pose and sides, and where the box's axes come from, in the anchor's frame at
    its ``stamp``: empty messages (and an empty source) when the estimate has no cloud."""
    header = Header(frame_id=frame_id, stamp=stamp)
    if result.depth is None or result.object is None:
        return PointCloud2(header=header), PoseStamped(header=header), Vector3(), ""
    cloud = points_to_cloud(result.depth.cloud.points, result.depth.cloud.colours, frame_id, stamp)
    size = Vector3(x=float(result.object.size[0]), y=float(result.object.size[1]), z=float(result.object.size[2]))
    return cloud, PoseStamped(header=header, pose=matrix_to_pose(result.object.pose)), size, result.object.axes_source


def next_view_message(result: PipelineResult, frame_id: str, stamp) -> PoseStamped:
    """The suggested next camera in the anchor's frame at its ``stamp`` (``PipelineResult.next_view``)."""
    return PoseStamped(header=Header(frame_id=frame_id, stamp=stamp), pose=matrix_to_pose(result.next_view.pose))


def result_message(result: PipelineResult, headers: Sequence[Header], frame_id: str, run_id: int,
                   seconds: float) -> EstimatePoses.Result:
    """A SUCCEEDED result: the poses as ``~/poses`` publishes them (the anchor's stamp, ``frame_id``), one
    ViewEstimate per view, the object (``object_messages``) and the next view; ``headers`` are the views' image
    headers, the anchor first."""
    solved = result.solver_result
    cloud, pose, size, axes = object_messages(result, frame_id, headers[0].stamp)
    return Result(
        error_code=Result.SUCCEEDED, run_id=run_id,
        poses=poses_to_pose_array(result.poses, frame_id, headers[0].stamp),
        views=view_estimates(result, headers), object_distance=float(result.object_distance),
        distance_source=result.distance_source, anchor_polar_deg=float(result.anchor_polar_deg),
        anchor_polar_source=result.polar_source, forward_samples=solved.forward_samples,
        backward_samples=solved.backward_samples,
        stages=[SolverStage(name=name, forward_samples=forward, backward_samples=backward)
                for name, (forward, backward) in solved.stage_samples.items()],
        solver_note=solved.note, seconds=float(seconds), object_cloud=cloud, object_pose=pose, object_size=size,
        object_axes=axes, next_view=next_view_message(result, frame_id, headers[0].stamp),
        next_view_gain=float(result.next_view.gain),
        next_view_settles=-1 if result.next_view.view is None else int(result.next_view.view),
        next_view_reason=result.next_view.reason)


def action_result_details(result: EstimatePoses.Result) -> dict[str, Any]:
    """What ``idpose_core.pipeline.result_details`` gives for the same estimate (its angles and distances
    rounded to the message's float32)."""
    views = [ViewReport(view.mask_method, view.mask_note, _none_if_nan(view.roll_deg), _none_if_nan(view.polar_deg),
                        _none_if_nan(view.object_distance), touches_border=view.touches_border,
                        reliable=view.reliable, refinement=refinement_of(view),
                        mask_confidence=float(view.mask_confidence),
                        mask_pass_change=float(view.mask_pass_change)) for view in result.views]
    return estimate_details(views, result.anchor_polar_deg, result.anchor_polar_source, result.object_distance,
                            result.distance_source, result.forward_samples, result.backward_samples,
                            {stage.name: (stage.forward_samples, stage.backward_samples) for stage in result.stages},
                            result.solver_note)


def view_set_estimate(result: EstimatePoses.Result) -> ViewSetEstimate:
    """The evaluators' view of a SUCCEEDED result: poses, per non-anchor view score and ambiguity, details and the
    object cloud (when the result has one)."""
    others = result.views[1:]
    cloud = ObjectCloud(*cloud_to_points(result.object_cloud)) if result.object_axes else None
    return ViewSetEstimate(poses=np.stack([pose_to_matrix(pose) for pose in result.poses.poses]),
                           scores=np.array([view.score for view in others], dtype=np.float64),
                           ambiguous=np.array([view.ambiguous for view in others], dtype=bool),
                           seconds=float(result.seconds), details=action_result_details(result), cloud=cloud)
