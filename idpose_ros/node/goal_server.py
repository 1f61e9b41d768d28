"""The ``EstimatePoses`` action on ``~/estimate_poses``: a goal starts the node's one estimate run, hears its
progress as feedback, can cancel it, and ends with its typed result."""
from __future__ import annotations

import time
from typing import Any, Protocol

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.lifecycle import LifecycleNode
from rclpy.qos import QoSProfile

from idpose_core.solver import SolverConfig
from idpose_interfaces.action import EstimatePoses
from idpose_ros.node.estimate_run import EstimateRefused, EstimateRun, refusal_result
from idpose_ros.node.parameters import SOLVER_PARAMETERS
from idpose_ros.node.raw_image import RawImage
from idpose_ros.node.view_buffer import ImageRefused, View

Result = EstimatePoses.Result
FEEDBACK_PERIOD = 0.5  # s between two feedback messages of a goal
CANCEL_POLL = 0.05  # s between two looks of a goal at its cancel request


class Estimator(Protocol):
    """What a goal needs of the node."""

    def require_active(self, what: str) -> None: ...
    def buffered_views(self) -> list[View]: ...
    def prepare(self, image: RawImage) -> View: ...
    def parameter_values(self) -> dict[str, Any]: ...
    def start_estimate(self, views: list[View], values: dict[str, Any]) -> EstimateRun: ...
    def cancel_run(self, cause: str) -> int | None: ...
    def last_run_id(self) -> int: ...


def serve_goals(node: LifecycleNode, estimator: Estimator, qos: QoSProfile) -> ActionServer:
    """The action server; goals wait on their run in the executor's threads, so they must not block each other or
    the services (a reentrant group)."""
    return ActionServer(node, EstimatePoses, "~/estimate_poses", lambda handle: execute_goal(estimator, handle),
                        goal_callback=lambda goal: GoalResponse.ACCEPT,
                        cancel_callback=lambda goal_handle: CancelResponse.ACCEPT,
                        callback_group=ReentrantCallbackGroup(), goal_service_qos_profile=qos,
                        result_service_qos_profile=qos, cancel_service_qos_profile=qos)


def execute_goal(estimator: Estimator, goal_handle: ServerGoalHandle) -> EstimatePoses.Result:
    """Run the goal's estimate (or refuse it at once with the reason), with feedback every FEEDBACK_PERIOD s;
    a cancel request stops it within a model module (the buffered views stay)."""
    try:
        estimator.require_active("the EstimatePoses goal")
        run = estimator.start_estimate(goal_views(estimator, goal_handle.request),
                                       goal_values(estimator.parameter_values(), goal_handle.request))
    except EstimateRefused as refusal:
        goal_handle.abort()
        return refusal_result(refusal, estimator.last_run_id())
    cancel_asked = False
    goal_handle.publish_feedback(run.feedback())
    next_feedback = time.monotonic() + FEEDBACK_PERIOD
    while not run.finished.wait(CANCEL_POLL):
        if goal_handle.is_cancel_requested and not cancel_asked:
            cancel_asked = estimator.cancel_run("an EstimatePoses cancel") is not None
        if time.monotonic() >= next_feedback:
            goal_handle.publish_feedback(run.feedback())
            next_feedback = time.monotonic() + FEEDBACK_PERIOD
    result = run.result
    if result.error_code == Result.SUCCEEDED:
        goal_handle.succeed()
    elif result.error_code == Result.CANCELED and goal_handle.is_cancel_requested:
        goal_handle.canceled()
    else:
        goal_handle.abort()
    return result


def goal_views(estimator: Estimator, goal: EstimatePoses.Goal) -> list[View]:
    """The goal's images as views (matched with the inputs on the node's topics by stamp, like captured
    images), or the buffered views when it has none; EstimateRefused (INVALID_GOAL) names a bad image."""
    if not goal.images:
        return estimator.buffered_views()
    if len(goal.images) < 2:
        raise EstimateRefused(Result.INVALID_GOAL,
                              f"a goal needs at least 2 images (the anchor first), got {len(goal.images)}")
    views = []
    for index, image in enumerate(goal.images):
        try:
            views.append(estimator.prepare(RawImage(image, f"goal image {index}")))
        except ImageRefused as exc:
            raise EstimateRefused(Result.INVALID_GOAL, str(exc)) from exc
    return views


def goal_values(values: dict[str, Any], goal: EstimatePoses.Goal) -> dict[str, Any]:
    """The node's parameter values, with the goal's solver preset (if named) in place of its solver ones."""
    if not goal.preset:
        return values
    try:
        config = SolverConfig.preset(goal.preset)
    except ValueError as exc:
        raise EstimateRefused(Result.INVALID_GOAL, f"preset: {exc}") from exc
    return {**values, "preset": goal.preset, **{name: getattr(config, name) for name in SOLVER_PARAMETERS}}
