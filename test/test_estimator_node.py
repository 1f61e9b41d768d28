"""The idpose_estimator node in-process with real rclpy: topics, services, parameters, results.

Every test talks to the node through ROS only (``node_harness``: a probe node publishes images, calls services
and subscribes to the outputs); ``EstimatorNode.status()`` is read to wait for images to land. Reduced for
speed as ``node_harness`` says; torch on one thread (test/conftest.py). Nothing here checks accuracy: the tiny
model is random (see test_pipeline.py).
"""
from __future__ import annotations

from typing import Any

import cv2
import numpy as np
import pytest
from geometry_msgs.msg import Quaternion, QuaternionStamped
from node_harness import TIMEOUT, header, mixed_encodings
from rcl_interfaces.msg import Log
from rclpy.exceptions import InvalidParameterValueException
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from sensor_msgs.msg import CompressedImage, Image
from std_srvs.srv import Trigger

from idpose_core.model_loading import load_predictor
from idpose_core.pipeline import ViewInput, estimate_view_poses
from idpose_ros.node.estimator_node import EstimatorNode
from idpose_ros.node.parameters import current_values, pipeline_settings
from msg_adapters import array_to_image, compressed_to_rgb, image_to_rgb, pose_to_matrix

pytestmark = pytest.mark.slow  # every test here starts a node or a process, or takes seconds


def test_views_in_several_encodings_give_a_pose_array_in_the_anchor_frame(harness, object_views, wait_for,
                                                                         tiny_model_dir):
    h = harness(diagnostics_period=0.1, variant="naive")  # naive: 3 anchor pairs to explore instead of 6
    assert h.call("estimate").message == "need at least 2 buffered views to estimate, have 0"
    messages = mixed_encodings(object_views)
    malformed = [
        Image(header=header("cam", 50), encoding="rgb8", height=64, width=64, step=192, data=b"\x00" * 10),
        Image(header=header("cam", 51), encoding="no_such_encoding", height=2, width=2, step=6, data=b"\x00" * 12),
        CompressedImage(header=header("cam", 52), format="png", data=b"not a png at all"),
    ]
    h.send_view(messages[0])
    h.send_view(messages[1])
    for bad in malformed:  # mid-stream: logged and dropped, the buffer untouched
        h.send(bad)
    h.send_view(messages[2])
    h.send_view(messages[3])
    assert h.node.status().views_buffered == 4
    reasons = ("refused Image rgb8 on image: Image.data has 10 bytes", "encoding 'no_such_encoding' is not supported",
               "refused CompressedImage png on image/compressed: CompressedImage.data (16 bytes) is not a png")
    wait_for(lambda: any(reason in line for line in h.logged("refused") for reason in reasons),
             "the malformed-message warning on /rosout (one line per 5 s: whichever came first)")

    started = h.call("estimate")
    assert started.success and started.message == "estimating the poses of 4 views (run 1)"
    (poses,) = wait_for(lambda: h.poses, "the PoseArray")
    assert poses.header.frame_id == "anchor_cam"
    assert (poses.header.stamp.sec, poses.header.stamp.nanosec) == (42, 7)
    assert len(poses.poses) == 4
    matrices = np.stack([pose_to_matrix(p) for p in poses.poses])
    quaternions = np.array([[p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w] for p in poses.poses])
    np.testing.assert_allclose(np.linalg.norm(quaternions, axis=1), 1.0, atol=1e-9)
    np.testing.assert_allclose(matrices[0], np.eye(4), atol=1e-9)

    # The node ran exactly the shared pipeline on exactly these decoded views, in capture order.
    decoded = [ViewInput(*(image_to_rgb(m) if isinstance(m, Image) else compressed_to_rgb(m))) for m in messages]
    settings = pipeline_settings(current_values(h.node))
    assert settings.image_size == 32
    expected = estimate_view_poses(load_predictor(str(tiny_model_dir)), decoded, settings)
    np.testing.assert_allclose(matrices, expected.poses, atol=1e-6)

    markers = wait_for(lambda: h.markers, "the markers")[0]
    assert {m.header.frame_id for m in markers.markers} == {"anchor_cam"}
    mosaic = wait_for(lambda: h.views, "the views image")[0]
    assert (mosaic.encoding, mosaic.height, mosaic.width, mosaic.header.frame_id) == ("rgb8", 32, 4 * 32, "anchor_cam")
    wait_for(lambda: any(h.logged("estimate: refinement 100 %")), "the progress log")

    def last_diagnostics() -> dict[str, str]:
        ours = [s for array in h.diagnostics for s in array.status if s.name.startswith("idpose_estimator")]
        return {kv.key: kv.value for kv in ours[-1].values} if ours else {}
    report = wait_for(lambda: (d := last_diagnostics()) and "view_3_score" in d and d, "diagnostics with scores")
    assert (report["state"], report["run_id"], report["views_buffered"], report["model"]) == (
        "idle", "1", "4", "loaded")
    assert float(report["last_run_seconds"]) > 0 and "view_4_score" not in report
    assert h.state() == "idle" and h.node.status().views_buffered == 4, "a finished estimate keeps the views"


def test_cancel_and_reset_during_a_run(harness, object_views, wait_for):
    h = harness(refine_steps_per_view=1_000_000, average_last=1)
    for msg in mixed_encodings(object_views)[:2]:
        h.send_view(msg)
    assert h.call("cancel").message == "no estimate is running"

    assert h.call("estimate").success
    wait_for(lambda: h.node.status().stage == "refinement", "the refinement stage")
    busy = h.call("estimate")
    assert not busy.success and "busy" in busy.message
    cancelled = h.call("cancel")
    assert cancelled.success and cancelled.message == "cancelling the estimate (run 1); the 2 views stay buffered"
    wait_for(lambda: h.state() == "idle", "the cancelled run to stop", timeout=10.0)
    assert h.node.status().last_error == "cancelled" and h.node.status().views_buffered == 2
    wait_for(lambda: h.logged("cancelled by ~/cancel; the 2 buffered views stay for a retry"), "the cancel log line")

    retry = h.call("estimate")
    assert retry.success and retry.message.endswith("(run 2)"), "a cancelled estimate leaves the buffer for a retry"
    assert h.node.status().run_id == 2
    wait_for(lambda: h.node.status().stage == "refinement", "the refinement stage")
    reset = h.call("reset")
    assert reset.success and reset.message == "dropped 2 views (cancelled the running estimate)"
    assert h.node.status().views_buffered == 0, "~/reset answers at once, without waiting for the worker"
    assert h.call("estimate").message == "need at least 2 buffered views to estimate, have 0"
    wait_for(lambda: h.logged("(run 2) stopped"), "the cancelled run to stop", timeout=10.0)
    (stopped,) = h.logged("(run 2) stopped")
    assert stopped.endswith("cancelled by ~/reset; its views were dropped") and not h.logged("views are kept")
    wait_for(lambda: h.state() == "idle", "the idle state")
    assert h.poses == [], "a cancelled estimate publishes nothing"


def test_on_request_capture_lazy_model_and_automatic_estimate(harness, object_views, wait_for):
    h = harness(capture_mode="on_request", load_model_at_startup=False, views_per_estimate=2,
                anchor_frame="object_frame", object_distance=0.5)
    assert h.node.status().model == "not loaded"
    refused = h.call("capture")
    assert not refused.success and refused.message == "no new image received since the last capture"
    (rgb0, _), (rgb1, _) = object_views[:2]
    for rgb, sec in ((rgb0, 10), (rgb1, 11)):
        mono = array_to_image(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY), "mono8", header("cam_optical", sec))
        h.send(mono)
        answer = wait_for(lambda: (a := h.call("capture")).success and a, "a capture of the published image")
        assert answer.message.startswith(f"captured view {sec - 9}")
    (poses,) = wait_for(lambda: h.poses, "the PoseArray of the automatic estimate")
    assert poses.header.frame_id == "object_frame" and poses.header.stamp.sec == 10 and len(poses.poses) == 2
    assert h.node.status().model == "loaded"
    distance = np.linalg.norm([poses.poses[1].position.x, poses.poses[1].position.y, poses.poses[1].position.z])
    assert 0 < distance < 4 * 0.5, "positions are on the object_distance scale"


def test_a_missing_model_keeps_the_node_up_and_refuses_estimates(harness, object_views, wait_for, tmp_path):
    missing = tmp_path / "zero123-xl"
    h = harness(model_path=str(missing))
    wait_for(lambda: h.state() == "failed", "the model load to fail")
    assert h.node.lifecycle_state == "unconfigured", "configure fails with the load, so the node never activates"
    refusal = h.call("estimate")
    assert not refusal.success
    assert refusal.message.startswith(f"no model available: ModelLoadError: {missing}: no such folder or file")
    assert "huggingface" in refusal.message, "the reason says what to download"
    errors = wait_for(lambda: [e for e in h.logs if e.level == Log.ERROR], "the error log")
    assert h.call("reset").success  # logged after anything the failed load logged: /rosout keeps the node's order
    wait_for(lambda: h.logged("reset: dropped 0 views"), "the reset's log line")
    assert len([e for e in h.logs if e.level == Log.ERROR]) == 1 and str(missing) in errors[0].msg
    assert h.node.status().model.startswith("unavailable")


def test_parameters_are_checked_through_the_parameter_service(harness, wait_for):
    h = harness()
    client = AsyncParameterClient(h.probe, "idpose_estimator")
    assert client.wait_for_services(TIMEOUT)

    def set_one(name: str, value: Any):
        future = client.set_parameters([Parameter(name, value=value)])
        return wait_for(future.result, f"setting {name}").results[0]

    assert "out of range" in set_one("max_views", 100).reason.lower()
    assert "capture_mode must be one of auto, on_request" in set_one("capture_mode", "burst").reason
    assert "read-only" in set_one("model_path", "/elsewhere").reason.lower()
    assert set_one("max_views", 3).successful
    assert h.node.status().max_views == 3, "the buffer bound follows the parameter"


def test_an_invalid_start_up_parameter_is_refused_with_its_reason(ros_context):
    with pytest.raises(InvalidParameterValueException, match="variant must be one of full, tr, naive"):
        EstimatorNode(context=ros_context, namespace="/bad_start",
                      parameter_overrides=[Parameter("variant", value="best")])


def test_on_request_capture_decodes_only_the_image_it_keeps_and_refuses_a_bad_one(harness, object_views, png_bomb):
    h = harness(capture_mode="on_request")
    (rgb, alpha) = object_views[0]
    bomb = CompressedImage(header=header("cam", 1), format="png", data=png_bomb)
    noise = np.random.default_rng(0).integers(0, 256, (64, 64, 3), dtype=np.uint8)
    speck = np.dstack([rgb, np.where(np.arange(64)[:, None] + np.arange(64) < 6, 255, 0).astype(np.uint8)])

    def latest(msg: Image | CompressedImage) -> Trigger.Response:
        """Publish one image, wait until the node has it, and ask ~/capture to keep it."""
        received = h.node.status().images_received
        h.send(msg)
        h.wait_for(lambda: h.node.status().images_received == received + 1, "the image to arrive")
        return h.call("capture")

    refused = latest(bomb)
    assert not refused.success and refused.message == (
        "CompressedImage png on image/compressed: CompressedImage is 12000x12000 = 144000000 pixels, more than the "
        "limit of 16777216; refused before decoding (max_image_pixels)")
    h.wait_for(lambda: h.logged("~/capture refused CompressedImage png on image/compressed: CompressedImage is "
                                "12000x12000"), "the refusal on /rosout")
    for bad, reason in ((array_to_image(rgb[:8, :8].copy(), "rgb8", header("cam", 2)),
                         "Image rgb8 on image is 8x8 px, too small (at least 32 px a side)"),
                        (array_to_image(speck, "rgba8", header("cam", 3)),
                         "Image rgba8 on image: the object (alpha mask) is only 6x6 px, too small to compare")):
        answer = latest(bad)
        assert not answer.success and answer.message.startswith(reason), answer.message
    assert h.node.status().views_buffered == 0

    received = h.node.status().images_received
    for _ in range(5):  # a stream: only the latest message is decoded, and only on ~/capture
        h.send(bomb)
    h.wait_for(lambda: h.node.status().images_received == received + 5, "the stream to arrive")
    kept = latest(array_to_image(np.dstack([rgb, alpha]), "rgba8", header("cam", 4)))
    assert kept.success and kept.message == "captured view 1 (Image rgba8)"
    assert latest(array_to_image(noise, "rgb8", header("cam", 5))).success, "noise has no alpha: checked later"
    assert h.call("estimate").success
    h.wait_for(lambda: h.state() == "failed", "the estimate to refuse the noise view")
    assert h.node.status().last_error == "PreprocessingError: view 1: no object found (empty grabcut mask)"
    assert h.node.status().views_buffered == 2 and h.poses == []


def test_views_from_two_frames_are_flagged_and_an_empty_anchor_frame_falls_back(harness, object_views):
    h = harness()
    (rgb0, alpha0), (rgb1, alpha1) = object_views[:2]
    h.send_view(array_to_image(np.dstack([rgb0, alpha0]), "rgba8", header("", 1)))
    h.send_view(array_to_image(np.dstack([rgb1, alpha1]), "rgba8", header("other_camera", 2)))
    h.wait_for(lambda: h.logged("view 2 is in frame 'other_camera' but the anchor in ''"), "the mixed-frame warning")
    assert h.call("estimate").success
    (poses,) = h.wait_for(lambda: h.poses, "the PoseArray")
    assert poses.header.frame_id == "idpose_anchor"
    assert h.logged("the anchor image has no header.frame_id and anchor_frame is not set: publishing the poses in "
                    "frame 'idpose_anchor'")


def test_gravity_required_refuses_a_view_without_it_and_late_depth_is_attached(harness, object_views):
    """With gravity: required, ~/capture refuses an image no orientation matches; one matched within
    input_tolerance is kept upright-aware, and a depth image published after its view is attached."""
    h = harness(capture_mode="on_request", gravity="required")
    orientation = h.probe.create_publisher(QuaternionStamped, "camera_orientation", 10)
    depth = h.probe.create_publisher(Image, "depth", 10)
    h.wait_for(lambda: orientation.get_subscription_count() and depth.get_subscription_count(),
               "the node's input subscriptions")
    rgb, alpha = object_views[0]

    def latest(msg: Image) -> Trigger.Response:
        received = h.node.status().images_received
        h.send(msg)
        h.wait_for(lambda: h.node.status().images_received == received + 1, "the image to arrive")
        return h.call("capture")

    refused = latest(array_to_image(np.dstack([rgb, alpha]), "rgba8", header("cam", 10)))
    assert not refused.success and "no Imu or orientation message received; gravity: required" in refused.message
    level = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)  # an optical frame whose z is up: looking straight up
    orientation.publish(QuaternionStamped(header=header("base", 20), quaternion=level))
    h.wait_for(lambda: h.node._intake.sync.live(h.node.get_clock().now().nanoseconds) >= {"orientation"},
               "the orientation to arrive")
    far = latest(array_to_image(np.dstack([rgb, alpha]), "rgba8", header("cam", 21)))
    assert not far.success and "no orientation within 0.02 s of the image stamp" in far.message
    depth.publish(array_to_image(np.full((64, 64), 500, np.uint16), "16UC1", header("cam", 30)))
    h.wait_for(lambda: "depth" in h.node._intake.sync.live(h.node.get_clock().now().nanoseconds), "a depth image")
    orientation.publish(QuaternionStamped(header=header("base", 40), quaternion=level))
    kept = latest(array_to_image(np.dstack([rgb, alpha]), "rgba8", header("cam", 40)))
    assert kept.success and kept.message == "captured view 1 (Image rgba8, with gravity, depth pending)"
    depth.publish(array_to_image(np.full((64, 64), 500, np.uint16), "16UC1", header("cam", 40)))
    h.wait_for(lambda: not h.node._buffer.snapshot()[0].pending, "the late depth image to be attached")
    view = h.node._buffer.snapshot()[0].input
    np.testing.assert_allclose(view.gravity_up, [0.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(view.depth, 0.5)
