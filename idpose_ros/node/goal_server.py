"""The ``EstimatePoses`` action on ``~/estimate_poses``: a goal starts the node's one estimate run, hears its
progress as feedback, can cancel it, and ends with its typed result."""
from __future__ import annotations

import time
from collections.abc import Callable
from functools import partial
from typing import Any

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.lifecycle import LifecycleNode
from rclpy.qos import QoSProfile

from idpose_interfaces.action import EstimatePoses
from idpose_ros.node.estimate_run import EstimateRefused, refusal_result
from idpose_ros.node.estimation import Estimation
from idpose_ros.node.parameters import preset_values
from idpose_ros.node.raw_image import RawImage
from idpose_ros.node.run_state import CancelCause
from idpose_ros.node.view_buffer import ImageRefused, View
from idpose_ros.node.view_intake import ViewIntake

Result = EstimatePoses.Result
FEEDBACK_PERIOD = 0.5  # s between two feedback messages of a goal
CANCEL_POLL = 0.05  # s between two looks of a goal at its cancel request


def serve_goals(node: LifecycleNode, estimation: Estimation, intake: ViewIntake, qos: QoSProfile) -> ActionServer:
    """The action server; goals wait on their run in the executor's threads, so they must not block each other or
    the services (a reentrant group)."""
    return ActionServer(node, EstimatePoses, "~/estimate_poses", partial(execute_goal, estimation, intake),
                        goal_callback=lambda goal: GoalResponse.ACCEPT,
                        cancel_callback=lambda goal_handle: CancelResponse.ACCEPT,
                        callback_group=ReentrantCallbackGroup(), goal_service_qos_profile=qos,
                        result_service_qos_profile=qos, cancel_service_qos_profile=qos)


def execute_goal(estimation: Estimation, intake: ViewIntake, goal_handle: ServerGoalHandle) -> EstimatePoses.Result:
    """Run the goal's estimate (or refuse it at once with the reason), with feedback every FEEDBACK_PERIOD s;
    a cancel request stops it within a model module (the buffered views stay)."""
    goal = goal_handle.request
    try:
        estimation.require_active("the EstimatePoses goal")
        run = estimation.start(goal_views(goal, estimation.buffered_views, intake.prepare),
                               goal_values(estimation.values, goal))
    except EstimateRefused as refusal:
        goal_handle.abort()
        return refusal_result(refusal, estimation.run_id)
    cancel_asked = False
    goal_handle.publish_feedback(run.feedback())
    next_feedback = time.monotonic() + FEEDBACK_PERIOD
    while not run.finished.wait(CANCEL_POLL):
        if goal_handle.is_cancel_requested and not cancel_asked:
            cancel_asked = estimation.cancel(CancelCause.GOAL) is not None
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


def goal_views(goal: EstimatePoses.Goal, buffered_views: Callable[[], list[View]],
               prepare: Callable[[RawImage], View]) -> list[View]:
    """The goal's images as views (``prepare`` matches each with the inputs on the node's topics by stamp, like a
    captured image), or the buffered views when it has none; EstimateRefused (INVALID_GOAL) names a bad image."""
    if not goal.images:
        return buffered_views()
    if len(goal.images) < 2:
        raise EstimateRefused(Result.INVALID_GOAL,
                              f"a goal needs at least 2 images (the anchor first), got {len(goal.images)}")
    views = []
    for index, image in enumerate(goal.images):
        try:
            views.append(prepare(RawImage(image, f"goal image {index}")))
        except ImageRefused as exc:
            raise EstimateRefused(Result.INVALID_GOAL, str(exc)) from exc
    return views


def goal_values(values: dict[str, Any], goal: EstimatePoses.Goal) -> dict[str, Any]:
    """The node's parameter values, with the goal's solver preset (if named) in place of its solver ones."""
    if not goal.preset:
        return values
    try:
        return {**values, "preset": goal.preset, **preset_values(goal.preset)}
    except ValueError as exc:
        raise EstimateRefused(Result.INVALID_GOAL, f"preset: {exc}") from exc
