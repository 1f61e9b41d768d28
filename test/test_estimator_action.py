"""The estimator's robot API with real rclpy clients: the EstimatePoses action (goal, feedback, cancel, typed
result), its refusals, a 50-goal burst, the lifecycle walked by hand, and the poses on TF.

Same reduced setting as test_estimator_node.py (tiny random model, 32 px views, a minimal solver):
nothing here checks accuracy.
"""
from __future__ import annotations

import math
import sys
import time
import types
from typing import Any

import numpy as np
import pytest
from action_msgs.msg import GoalStatus
from geometry_msgs.msg import Pose, PoseArray, PoseStamped
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from node_harness import TIMEOUT, ActionProbe, header, mixed_encodings
from rclpy.lifecycle import LifecycleNode, LifecyclePublisher
from sensor_msgs.msg import Image

from idpose_core.solver import SolverConfig
from idpose_interfaces.action import EstimatePoses
from idpose_ros.node.result_publisher import RESULT_QOS
from idpose_ros.node.tf_broadcast import PoseBroadcaster
from msg_adapters import pose_to_matrix

pytestmark = pytest.mark.slow  # every test here starts a node or a process, or takes seconds

Result = EstimatePoses.Result
LONG_RUN = dict(refine_steps_per_view=1_000_000, average_last=1)  # runs until cancelled
BURST = 50


def image_messages(object_views) -> list[Image]:
    return [m for m in mixed_encodings(object_views) if isinstance(m, Image)]


@pytest.fixture
def node(harness):
    """A node with the fast solver and an action client: (harness, ActionProbe)."""
    def make(**overrides: Any):
        h = harness(capture_mode="on_request", **overrides)
        return h, ActionProbe(h)
    return make


def test_a_two_image_goal_gives_typed_poses_in_the_anchor_frame_with_feedback(node, object_views, wait_for):
    h, action = node(refine_steps_per_view=60, diagnostics_period=0.1)  # a run long enough for some feedback
    images = image_messages(object_views)
    status, result = action.run(images)
    assert status == GoalStatus.STATUS_SUCCEEDED
    assert result.error_code == Result.SUCCEEDED and result.error_message == ""
    assert result.run_id == 1 and h.node.status().run_id == 1
    assert result.poses.header.frame_id == "anchor_cam" and result.poses.header.stamp.sec == 42
    np.testing.assert_allclose(pose_to_matrix(result.poses.poses[0]), np.eye(4), atol=1e-9)
    (published,) = wait_for(lambda: h.poses, "the PoseArray on ~/poses")
    assert published == result.poses, "the result's poses are exactly what ~/poses publishes"
    assert [v.header for v in result.views] == [m.header for m in images]
    anchor, other = result.views
    assert anchor.confidence == 1.0 and not anchor.ambiguous and math.isnan(anchor.score)
    assert 0.0 <= other.confidence <= 1.0 and math.isfinite(other.score)
    assert anchor.pose == result.poses.poses[0] and other.pose == result.poses.poses[1]
    assert (anchor.mask_method, other.mask_method) == ("alpha", "threshold"), "rgba8 has alpha, bgr8 not"
    assert math.isnan(other.roll_deg) and other.polar_source == ""
    assert result.distance_source == "parameter" and result.object_distance == 1.0
    assert result.forward_samples == sum(s.forward_samples for s in result.stages) > 0
    assert [s.name for s in result.stages][:1] == ["exploration"]
    assert h.node.status().views_buffered == 0, "a goal's images are not added to the buffer"

    feedback = list(action.feedback)
    progress = [f.progress for f in feedback]
    print(f"\n{len(feedback)} feedback messages over {result.seconds:.2f} s; progress {progress}")
    assert len(feedback) >= max(1, math.floor(result.seconds)), "at least one feedback message a second"
    assert progress == sorted(progress) and all(0.0 <= p <= 1.0 for p in progress)
    assert all(f.seconds_elapsed >= 0.0 for f in feedback)
    assert feedback[-1].forward_samples <= result.forward_samples


def test_a_goal_on_the_buffered_views_keeps_them(node, object_views):
    h, action = node()
    for message in image_messages(object_views)[:2]:
        h.send(message)
        h.wait_for(lambda: h.call("capture").success, "a capture")
    status, result = action.run()
    assert result.error_code == Result.SUCCEEDED and len(result.poses.poses) == 2
    assert result.poses.header.frame_id == "anchor_cam"
    assert h.node.status().views_buffered == 2


def test_bad_goals_end_in_invalid_goal_naming_the_image_and_the_problem(node, object_views):
    h, action = node()
    images = image_messages(object_views)
    status, one = action.run(images[:1])
    assert status == GoalStatus.STATUS_ABORTED and one.error_code == Result.INVALID_GOAL
    assert one.error_message == "a goal needs at least 2 images (the anchor first), got 1"
    broken = Image(header=header("cam", 50), encoding="rgb8", height=64, width=64, step=192, data=b"\x00" * 10)
    _, bad = action.run([images[0], broken])
    assert bad.error_code == Result.INVALID_GOAL
    assert bad.error_message.startswith("Image rgb8 on goal image 1: Image.data has 10 bytes"), bad.error_message
    _, empty = action.run()
    assert empty.error_code == Result.INVALID_GOAL and "have 0" in empty.error_message
    _, preset = action.run(images, preset="fastest")
    assert preset.error_code == Result.INVALID_GOAL and "unknown solver preset 'fastest'" in preset.error_message
    assert h.state() == "idle" and h.node.status().run_id == 0, "no refused goal started a run"


def test_a_cancel_is_honoured_within_a_second_and_keeps_the_buffered_views(node, object_views):
    h, action = node(**LONG_RUN)
    for message in image_messages(object_views)[:2]:
        h.send(message)
        h.wait_for(lambda: h.call("capture").success, "a capture")
    handle = action.send()
    h.wait_for(lambda: any(f.stage == "refinement" for f in action.feedback), "feedback from the refinement")
    asked = time.monotonic()
    h.wait_for(handle.cancel_goal_async().result, "the cancel response")
    status, result = action.result(handle)
    latency = time.monotonic() - asked
    print(f"\ncancel latency: {latency * 1000:.0f} ms")
    assert status == GoalStatus.STATUS_CANCELED and result.error_code == Result.CANCELED
    assert result.error_message == "cancelled by an EstimatePoses cancel; the 2 buffered views stay for a retry"
    assert latency < 1.0
    assert h.node.status().views_buffered == 2 and h.state() == "idle"
    assert h.poses == [], "a cancelled estimate publishes nothing"


def test_a_burst_of_50_goals_is_answered_in_full_one_running(node, object_views):
    h, action = node(**LONG_RUN)
    images = image_messages(object_views)[:2]
    futures = [action.client.send_goal_async(EstimatePoses.Goal(images=images)) for _ in range(BURST)]
    handles = [h.wait_for(f.result, "a goal response") for f in futures]
    assert all(handle.accepted for handle in handles)
    h.wait_for(lambda: h.node.status().state == "estimating", "the one running goal")
    results = {}
    for handle in handles:
        future = handle.get_result_async()
        results[id(handle)] = future
    h.wait_for(lambda: sum(f.done() for f in results.values()) == BURST - 1, "the refusals of the others")
    refused = [f.result().result for f in results.values() if f.done()]
    assert {r.error_code for r in refused} == {Result.BUSY}
    assert {r.error_message for r in refused} == {"busy: the estimate (run 1) is running"}
    (running,) = [handle for handle in handles if not results[id(handle)].done()]
    assert h.node.status().run_id == 1 and h.node.status().views_buffered == 0
    h.wait_for(running.cancel_goal_async().result, "the cancel response")
    h.wait_for(results[id(running)].done, "the running goal's end")
    assert results[id(running)].result().result.error_code == Result.CANCELED
    h.wait_for(lambda: h.state() == "idle", "the idle state")
    status, again = action.run(images, preset="fast")
    assert again.error_code == Result.CANCELED or again.run_id == 2


def test_a_live_goal_without_gravity_runs_fast_and_the_result_says_why(node, object_views):
    _, action = node()
    status, result = action.run(image_messages(object_views), preset="live")
    assert status == GoalStatus.STATUS_SUCCEEDED and result.error_code == Result.SUCCEEDED
    assert "'fast' schedule" in result.solver_note and "no view's elevation is known" in result.solver_note
    refinement = {stage.name: stage.backward_samples for stage in result.stages}["refinement"]
    assert refinement == SolverConfig.preset("fast").refine_steps_per_view
    _, plain = action.run(image_messages(object_views), preset="fast")
    assert plain.error_code == Result.SUCCEEDED and plain.solver_note == ""


def lifecycle(h: Any) -> tuple[Any, Any]:
    change = h.probe.create_client(ChangeState, "idpose_estimator/change_state")
    get = h.probe.create_client(GetState, "idpose_estimator/get_state")
    assert change.wait_for_service(TIMEOUT) and get.wait_for_service(TIMEOUT)
    return change, get


def transition(h: Any, change: Any, transition_id: int) -> bool:
    future = change.call_async(ChangeState.Request(transition=Transition(id=transition_id)))
    return h.wait_for(future.result, f"lifecycle transition {transition_id}").success


def test_the_lifecycle_walked_with_autostart_off(node, object_views):
    h, action = node(autostart=False)
    change, get = lifecycle(h)
    state = lambda: h.wait_for(get.call_async(GetState.Request()).result, "the state").current_state.label  # noqa: E731
    images = image_messages(object_views)[:2]
    assert state() == "unconfigured" and h.node.status().model == "not loaded"
    _, refused = action.run(images)
    assert refused.error_code == Result.NOT_ACTIVE and "the node is unconfigured, not active" in refused.error_message

    assert transition(h, change, Transition.TRANSITION_CONFIGURE) and state() == "inactive"
    assert h.node.status().model == "loaded", "configure loads the model"
    _, inactive = action.run(images)
    assert inactive.error_code == Result.NOT_ACTIVE and "inactive" in inactive.error_message
    assert not h.call("capture").success and not h.call("estimate").success

    assert transition(h, change, Transition.TRANSITION_ACTIVATE) and state() == "active"
    _, done = action.run(images)
    assert done.error_code == Result.SUCCEEDED and done.run_id == 1

    assert transition(h, change, Transition.TRANSITION_DEACTIVATE) and state() == "inactive"
    assert action.run(images)[1].error_code == Result.NOT_ACTIVE
    assert h.node.status().model == "loaded", "deactivate keeps the model"
    assert transition(h, change, Transition.TRANSITION_CLEANUP) and state() == "unconfigured"
    assert h.node.status().model == "not loaded", "cleanup frees the model"
    assert transition(h, change, Transition.TRANSITION_CONFIGURE) and transition(
        h, change, Transition.TRANSITION_ACTIVATE)
    assert action.run(images)[1].run_id == 2, "configured again, it estimates again"
    assert transition(h, change, Transition.TRANSITION_ACTIVE_SHUTDOWN) and state() == "finalized"


def test_results_publish_only_while_active_and_stay_latched(node, object_views, wait_for, tf2_msgs):
    """The result topics and /tf are lifecycle publishers, on from activate to deactivate; /diagnostics is plain
    (it reports every state). The last result stays latched: a subscriber that joins while inactive gets it."""
    h, action = node(autostart=False)
    change, _ = lifecycle(h)
    managed = {p.topic_name.rsplit("/", 1)[1]: p for p in h.node.publishers if isinstance(p, LifecyclePublisher)}
    assert set(managed) == {"poses", "markers", "views", "object_cloud", "object_pose", "next_view", "tf"}
    assert any(p.topic_name == "/diagnostics" and not isinstance(p, LifecyclePublisher) for p in h.node.publishers)
    assert transition(h, change, Transition.TRANSITION_CONFIGURE)
    assert not any(p.is_activated for p in managed.values()), "inactive: nothing published"
    assert transition(h, change, Transition.TRANSITION_ACTIVATE)
    assert all(p.is_activated for p in managed.values())
    _, result = action.run(image_messages(object_views)[:2])
    assert result.error_code == Result.SUCCEEDED
    assert transition(h, change, Transition.TRANSITION_DEACTIVATE)
    assert not any(p.is_activated for p in managed.values())
    late: list[PoseArray] = []
    h.probe.create_subscription(PoseArray, "idpose_estimator/poses", late.append, RESULT_QOS)
    assert wait_for(lambda: late, "the latched poses, the node inactive") == [result.poses]
    assert h.poses == [result.poses], "published once, while active"


def test_deactivate_cancels_a_running_goal(node, object_views):
    h, action = node(**LONG_RUN)
    change, _ = lifecycle(h)
    handle = action.send(image_messages(object_views)[:2])
    h.wait_for(lambda: h.node.status().state == "estimating", "the running goal")
    assert transition(h, change, Transition.TRANSITION_DEACTIVATE)
    status, result = action.result(handle)
    assert status == GoalStatus.STATUS_ABORTED
    assert result.error_code == Result.CANCELED and "deactivate" in result.error_message


def test_each_estimate_is_broadcast_on_tf(node, object_views, tf2_msgs):
    from tf2_msgs.msg import TFMessage

    h, action = node(tf_prefix="arm_")
    received: list[TFMessage] = []
    h.probe.create_subscription(TFMessage, "/tf", received.append, 100)
    h.wait_for(lambda: h.probe.count_publishers("/tf") > 0, "the node's /tf publisher")
    _, result = action.run(image_messages(object_views))
    assert result.error_code == Result.SUCCEEDED
    (message,) = h.wait_for(lambda: received, "the transforms on /tf")
    assert [t.child_frame_id for t in message.transforms] == ["arm_view_0", "arm_view_1", "arm_next_view"]
    for transform, pose in zip(message.transforms, [*result.poses.poses, result.next_view.pose]):
        assert transform.header == result.poses.header, "in the anchor frame, at the anchor's stamp"
        assert (transform.transform.translation.x, transform.transform.rotation) == (pose.position.x, pose.orientation)


def test_tf2_ros_sends_only_while_active(ros_context, monkeypatch):
    """tf2_ros's broadcaster publishes through a plain publisher of its own: its sends pass only while the node is
    active, as a lifecycle publisher's (a stand-in tf2_ros records them)."""
    sent: list[list[Any]] = []
    monkeypatch.setitem(sys.modules, "tf2_ros", types.SimpleNamespace(
        TransformBroadcaster=lambda node: types.SimpleNamespace(sendTransform=sent.append)))
    node = LifecycleNode("tf_gate", context=ros_context)
    broadcaster = PoseBroadcaster(node, print)

    def broadcast() -> None:
        broadcaster.broadcast(PoseArray(header=header("anchor", 1), poses=[Pose()]), "p_", PoseStamped())

    broadcast()
    node.trigger_configure()
    broadcast()
    assert broadcaster.backend == "tf2_ros" and sent == [], "not active: nothing sent"
    node.trigger_activate()
    broadcast()
    assert [[transform.child_frame_id for transform in sent[0]]] == [["p_view_0", "p_next_view"]]
    node.trigger_deactivate()
    broadcast()
    assert len(sent) == 1
    node.destroy_node()
