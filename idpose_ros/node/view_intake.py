"""From the camera's messages to buffered views: images, and the depth, masks, intrinsics, gravity and region of
interest that go with them, matched by stamp.

Whatever a message holds, the node and the views it holds stay: a bad image is refused with the reason, a bad
input is logged (throttled) and dropped.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
from geometry_msgs.msg import PoseStamped, QuaternionStamped
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.lifecycle import LifecycleNode
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, Imu, RegionOfInterest

from idpose_core.preprocessing import PreprocessingError, precheck_view
from idpose_ros.node.flight_recorder import FlightRecorder, subscribe_tf
from idpose_ros.node.input_sync import IMAGE_INPUTS, GravityMode, InputSync
from idpose_ros.node.node_state import NodeState
from idpose_ros.node.raw_image import RawImage
from idpose_ros.node.view_buffer import CaptureMode, CaptureRefused, ImageRefused, View, ViewBuffer
from idpose_ros.view_decoding import ViewMessages, with_inputs
from msg_adapters import AdapterError, ImageTooLarge, pose_to_matrix, stamp_nanoseconds

THROTTLE = 5.0  # s between two log lines about refused images
# An IMU publishes hundreds of readings a second: a deep best-effort queue keeps them while a callback runs.
IMU_QOS = QoSProfile(depth=200, reliability=ReliabilityPolicy.BEST_EFFORT)


def view_inputs_text(view: View) -> str:
    """", with depth, gravity" etc. for the inputs a kept view has (and ", depth pending" for those still to come)."""
    have = [name for name, value in (("mask", view.input.mask), ("depth", view.input.depth),
                                     ("intrinsics", view.input.intrinsics), ("gravity", view.input.gravity_up),
                                     ("roi", view.input.roi)) if value is not None]
    pending = [f"{kind} pending" for kind in sorted(view.pending)]
    return "".join(f", {item}" for item in (["with " + ", ".join(have)] if have else []) + pending)


def arm_pose(gravity_source: tuple) -> np.ndarray | None:
    """The camera's optical frame (4, 4) in the fixed frame when its gravity came from one ``camera_pose`` message
    (a PoseStamped from the arm's kinematics), else None."""
    if len(gravity_source) == 1 and isinstance(gravity_source[0], PoseStamped):
        return pose_to_matrix(gravity_source[0].pose)
    return None


class ViewIntake:
    """The node's subscriptions to images and their inputs, and the one way an image becomes a view (``prepare``).

    ``state`` says whether images are taken now (active) and the node's current settings; ``on_kept(count)``
    hears of every view kept (``count`` views are then buffered).
    """

    def __init__(self, node: LifecycleNode, state: NodeState, buffer: ViewBuffer, sync: InputSync,
                 recorder: FlightRecorder, on_kept: Callable[[int], None]) -> None:
        self._node, self._state, self._buffer, self.sync, self._recorder = node, state, buffer, sync, recorder
        self._on_kept = on_kept
        self._logger = node.get_logger()
        self._roi: tuple[int, int, int, int] | None = None  # the latest region of interest, for views kept later
        self.images_received = 0  # counted by the image callbacks only (one callback group)

    def subscribe(self) -> None:
        """Images in one exclusive group (capture order is kept), their inputs in another."""
        node, images, inputs = self._node, MutuallyExclusiveCallbackGroup(), MutuallyExclusiveCallbackGroup()
        node.create_subscription(Image, "image", lambda msg: self._on_message(RawImage(msg, "image")),
                                 qos_profile_sensor_data, callback_group=images)
        node.create_subscription(CompressedImage, "image/compressed",
                                 lambda msg: self._on_message(RawImage(msg, "image/compressed")),
                                 qos_profile_sensor_data, callback_group=images)
        for kind in IMAGE_INPUTS:
            node.create_subscription(Image, kind, lambda msg, kind=kind: self._on_image_input(kind, msg),
                                     qos_profile_sensor_data, callback_group=inputs)
        node.create_subscription(CameraInfo, "camera_info", self.sync.add_camera_info, qos_profile_sensor_data,
                                 callback_group=inputs)
        if self.sync.gravity is not GravityMode.OFF:
            node.create_subscription(Imu, "imu", self._on_imu, IMU_QOS, callback_group=inputs)
            for kind, topic in ((QuaternionStamped, "camera_orientation"), (PoseStamped, "camera_pose")):
                node.create_subscription(kind, topic, self._on_orientation, qos_profile_sensor_data,
                                         callback_group=inputs)
        node.create_subscription(RegionOfInterest, "roi", self._on_roi, 10, callback_group=inputs)
        if self._recorder.on:
            self._logger.info(subscribe_tf(node, self._recorder, inputs))

    def capture(self) -> tuple[View, int]:
        """Keep the latest image as a view now (``~/capture``): the view and how many are buffered;
        ``ImageRefused`` (the image cannot be a view, logged) or ``CaptureRefused`` say why not."""
        try:
            view, count = self._buffer.keep_latest(self.prepare, self._now())
        except ImageRefused as exc:
            self._logger.warning(f"~/capture refused {exc}")
            raise
        self._kept(view, count)
        self._recorder.flush()  # a view the answer names is in the recording
        return view, count

    def prepare(self, image: RawImage) -> View:
        """Decode ``image`` (its size checked first) with the other inputs of its stamp and check it can be a view;
        ``ImageRefused`` says why not. Whatever goes wrong, the node and the views it holds stay.
        """
        name = f"{image.source} on {image.topic}"
        try:
            pixels = image.decode(self._state.settings.max_image_pixels)
            height, width = pixels.rgb.shape[:2]
            now = self._node.get_clock().now().nanoseconds
            matched = self.sync.match(stamp_nanoseconds(image.stamp), (width, height), now)
            if matched.gravity_problem:
                if self.sync.gravity is GravityMode.REQUIRED:
                    raise ImageRefused(f"{name}: no gravity reading for it ({matched.gravity_problem}; gravity: "
                                       "required)")
                self._logger.warning(f"{name}: kept without gravity ({matched.gravity_problem})",
                                     throttle_duration_sec=THROTTLE)
            roi = self._roi
            pixels = with_inputs(pixels, matched.depth, matched.mask, matched.camera_info, matched.gravity_up, roi,
                                 arm_pose(matched.gravity_source))
            precheck_view(pixels, name)
            received = (ViewMessages(image.message, matched.depth, matched.mask, matched.camera_info,
                                     matched.gravity_up, roi, matched.gravity_source) if self._recorder.on else None)
        except ImageRefused:
            raise
        except ImageTooLarge as exc:
            raise ImageRefused(f"{name}: {exc} (max_image_pixels)") from exc
        except AdapterError as exc:
            raise ImageRefused(f"{name}: {exc}") from exc
        except PreprocessingError as exc:  # it names the image itself
            raise ImageRefused(str(exc)) from exc
        except Exception as exc:  # an adapter bug must not kill the node or the views it holds
            raise ImageRefused(f"{name}: it failed to decode: {type(exc).__name__}: {exc}") from exc
        return View(pixels, frame_id=image.frame_id, stamp=image.stamp, source=image.source, pending=matched.pending,
                    received=received)

    def _on_message(self, image: RawImage) -> None:
        """Remember the image undecoded; in auto mode, keep it as a view when one is due. Ignored unless active."""
        if not self._state.active:
            return
        self.images_received += 1
        self._buffer.observe(image)
        settings = self._state.settings
        if settings.capture_mode != CaptureMode.AUTO or not self._buffer.due(self._now(), settings.min_view_interval):
            return
        try:
            view, count = self._buffer.keep_latest(self.prepare, self._now())
        except ImageRefused as exc:
            self._logger.warning(f"refused {exc}", throttle_duration_sec=THROTTLE)
            return
        except CaptureRefused as exc:
            self._logger.warning(f"not keeping the image: {exc}", throttle_duration_sec=THROTTLE)
            return
        self._kept(view, count)

    def _kept(self, view: View, count: int) -> None:
        self._recorder.view_kept(count, view)
        role = "anchor" if count == 1 else f"view {count}"
        height, width = view.input.rgb.shape[:2]
        self._logger.info(f"kept {role} ({view.source}, {width}x{height}, frame '{view.frame_id}'), {count} buffered")
        anchor = self._buffer.anchor()
        if count > 1 and anchor is not None and view.frame_id != anchor.frame_id:
            self._logger.warning(
                f"view {count} is in frame '{view.frame_id}' but the anchor in '{anchor.frame_id}': images from "
                "different cameras or publishers are mixed in one view set (call ~/reset between objects)")
        self._on_kept(count)

    def _on_image_input(self, kind: str, msg: Image) -> None:
        """A depth or mask image: kept for views to come, and given to kept views still waiting for it."""
        self.sync.add_image(kind, msg, self._node.get_clock().now().nanoseconds)

        def fill(view: View) -> View | None:
            if not self.sync.fits(kind, msg, stamp_nanoseconds(view.stamp)):
                return None
            try:
                done = replace(view, input=with_inputs(view.input, **{kind: msg}), pending=view.pending - {kind},
                               received=view.received and replace(view.received, **{kind: msg}))
                self._recorder.view_input(view, kind, msg)
                return done
            except AdapterError as exc:
                taken = stamp_nanoseconds(view.stamp) * 1e-9
                self._logger.warning(f"the {kind} image for a view taken at {taken:.3f} s is not used: {exc}",
                                     throttle_duration_sec=THROTTLE)
                return replace(view, pending=view.pending - {kind})

        self._buffer.complete(kind, fill)

    def _on_imu(self, msg: Imu) -> None:
        try:
            self.sync.add_imu(msg, self._node.get_clock().now().nanoseconds)
        except AdapterError as exc:
            self._logger.warning(f"dropped an imu message: {exc}", throttle_duration_sec=THROTTLE)

    def _on_orientation(self, msg: QuaternionStamped | PoseStamped) -> None:
        try:
            self.sync.add_orientation(msg, self._node.get_clock().now().nanoseconds)
        except AdapterError as exc:
            self._logger.warning(f"dropped a camera orientation: {exc}", throttle_duration_sec=THROTTLE)

    def _on_roi(self, msg: RegionOfInterest) -> None:
        """Views kept from now on look for their object here (an empty region clears it)."""
        self._roi = (msg.x_offset, msg.y_offset, msg.width, msg.height) if msg.width and msg.height else None

    def _now(self) -> float:
        return self._node.get_clock().now().nanoseconds * 1e-9
