"""The estimator's other inputs, matched to each view by stamp: depth, masks, CameraInfo and gravity.

Every topic is optional. Depth and mask images are kept for a short while and matched to a view's
stamp within ``tolerance`` (one that has not arrived yet when the view is kept is attached when it
does, see ``ViewBuffer.complete``); the latest CameraInfo whose size fits the image is used; gravity
comes from the accelerometer (its readings averaged over ``imu_window`` before the stamp, turned into
the optical frame by ``optical_from_imu``) or from the optical frame's orientation in a frame whose
+z is up, and is looked up when the view is kept. Thread-safe: the node's callbacks feed it while
services read it.
"""
from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np
from geometry_msgs.msg import PoseStamped, QuaternionStamped
from sensor_msgs.msg import CameraInfo, Image, Imu

from idpose_core.gravity import (
    IMU_WINDOW_S,
    GravityUnavailable,
    resting_window,
    up_from_acceleration,
    up_from_orientation,
)
from idpose_core.stamps import INPUT_TOLERANCE_S, match_stamps
from msg_adapters import imu_acceleration, orientation_rotation, stamp_nanoseconds


class GravityMode(StrEnum):
    """Whether views take gravity from the imu and camera orientation topics (the ``gravity`` parameter's choices)."""

    OFF = "off"  # not subscribed
    AUTO = "auto"  # when those topics publish
    REQUIRED = "required"  # a view without a gravity reading is refused


IMAGE_INPUTS = ("depth", "mask")
IMAGE_HISTORY = 30  # depth / mask messages kept (a second at 30 Hz)
IMU_HISTORY = 8000  # accelerometer readings kept (20 s at 400 Hz)
ORIENTATION_HISTORY = 2000  # orientations kept


@dataclass(frozen=True)
class Matched:
    """What the other topics hold for one view: depth and mask messages (None when none matches yet, with the
    kind in ``pending`` when its topic is live), CameraInfo, world up in the optical frame and the messages
    it came from (``gravity_source``: the Imu readings of the window, or one orientation), and why gravity
    is missing (``gravity_problem``)."""

    depth: Image | None = None
    mask: Image | None = None
    camera_info: CameraInfo | None = None
    gravity_up: np.ndarray | None = None
    pending: frozenset[str] = frozenset()
    gravity_problem: str = ""
    gravity_source: tuple[Imu | QuaternionStamped | PoseStamped, ...] = ()


@dataclass
class _Stream:
    """One input's recent messages (stamp, payload) and when the last one came (node clock, ns)."""

    items: deque = field(default_factory=deque)
    last_seen: int | None = None


class InputSync:
    """Recent depth, mask, CameraInfo, Imu and orientation messages, and their match to a view.

    ``active_ns``: a topic counts as live while its last message is younger than this.
    """

    def __init__(self, gravity: str = GravityMode.AUTO, optical_from_imu: np.ndarray | None = None,
                 imu_window: float = IMU_WINDOW_S, tolerance: float = INPUT_TOLERANCE_S, active: float = 5.0) -> None:
        try:
            self.gravity = GravityMode(gravity)
        except ValueError:
            raise ValueError(f"gravity must be one of {', '.join(GravityMode)}, got {gravity!r}") from None
        self.optical_from_imu = np.eye(3) if optical_from_imu is None else np.asarray(optical_from_imu, float)
        self.imu_window, self.tolerance = int(imu_window * 1e9), int(tolerance * 1e9)
        self.active = int(active * 1e9)
        self._lock = threading.Lock()
        self._streams = {kind: _Stream(deque(maxlen=IMAGE_HISTORY)) for kind in IMAGE_INPUTS}
        self._imu = _Stream(deque(maxlen=IMU_HISTORY))
        self._orientation = _Stream(deque(maxlen=ORIENTATION_HISTORY))
        self._camera_info: CameraInfo | None = None

    # ----- feeding ---------------------------------------------------------------------------------------------
    def add_image(self, kind: str, message: Image, now: int) -> None:
        """A depth or mask image (kept undecoded)."""
        with self._lock:
            stream = self._streams[kind]
            stream.items.append((stamp_nanoseconds(message.header.stamp), message))
            stream.last_seen = now

    def add_camera_info(self, message: CameraInfo) -> None:
        with self._lock:
            self._camera_info = message

    def add_imu(self, message: Imu, now: int) -> None:
        """An accelerometer reading; AdapterError for one without a direction."""
        reading = imu_acceleration(message)
        with self._lock:
            self._imu.items.append((stamp_nanoseconds(message.header.stamp), reading, message))
            self._imu.last_seen = now

    def add_orientation(self, message: QuaternionStamped | PoseStamped, now: int) -> None:
        """The optical frame's orientation in a z-up frame; AdapterError for one that is not a rotation."""
        up = up_from_orientation(orientation_rotation(message))
        with self._lock:
            self._orientation.items.append((stamp_nanoseconds(message.header.stamp), up, message))
            self._orientation.last_seen = now

    # ----- matching --------------------------------------------------------------------------------------------
    def live(self, now: int) -> set[str]:
        """The inputs whose topics sent something within ``active``: depth, mask, imu, orientation."""
        streams = {**self._streams, "imu": self._imu, "orientation": self._orientation}
        with self._lock:
            return {kind for kind, stream in streams.items()
                    if stream.last_seen is not None and now - stream.last_seen <= self.active}

    def image_match(self, kind: str, stamp: int) -> Image | None:
        """The kept depth or mask message nearest ``stamp`` within the tolerance, or None."""
        with self._lock:
            items = list(self._streams[kind].items)
        index = int(match_stamps([stamp], [s for s, _ in items], self.tolerance)[0])
        return items[index][1] if index >= 0 else None

    def fits(self, kind: str, message: Image, stamp: int) -> bool:
        """Whether a newly arrived depth or mask message belongs to a view taken at ``stamp``."""
        return abs(stamp_nanoseconds(message.header.stamp) - stamp) <= self.tolerance

    def gravity_up(self, stamp: int) -> np.ndarray:
        """World up in the optical frame at ``stamp`` (``gravity_reading``)."""
        return self.gravity_reading(stamp)[0]

    def gravity_reading(self, stamp: int) -> tuple[np.ndarray, tuple[Imu | QuaternionStamped | PoseStamped, ...]]:
        """World up in the optical frame at ``stamp`` and the messages it came from: the orientation topic's
        reading when one is within the tolerance, else the accelerometer's over the window.
        GravityUnavailable says why there is none."""
        with self._lock:
            orientations = list(self._orientation.items)
            imu = list(self._imu.items)
        if orientations:
            index = int(match_stamps([stamp], [s for s, _, _ in orientations], self.tolerance)[0])
            if index >= 0:
                return orientations[index][1], (orientations[index][2],)
        if imu:
            chosen = resting_window(np.array([s for s, _, _ in imu]), stamp, self.imu_window, self.tolerance)
            acceleration = np.stack([a for _, a, _ in imu])[chosen].mean(axis=0)
            return (up_from_acceleration(acceleration, self.optical_from_imu),
                    tuple(message for (_, _, message), used in zip(imu, chosen) if used))
        if orientations:
            raise GravityUnavailable(f"no orientation within {self.tolerance * 1e-9:g} s of the image stamp")
        raise GravityUnavailable("no Imu or orientation message received")

    def match(self, stamp: int, size: tuple[int, int], now: int) -> Matched:
        """Everything the other topics hold for a view taken at ``stamp`` (``size`` (width, height))."""
        live = self.live(now)
        found = {kind: self.image_match(kind, stamp) for kind in IMAGE_INPUTS}
        pending = frozenset(kind for kind in IMAGE_INPUTS if found[kind] is None and kind in live)
        with self._lock:
            info = self._camera_info
        if info is not None and (info.width, info.height) != size:
            info = None
        up, problem, source = None, "", ()
        if self.gravity is GravityMode.REQUIRED or (self.gravity is GravityMode.AUTO and live & {"imu", "orientation"}):
            try:
                up, source = self.gravity_reading(stamp)
            except GravityUnavailable as err:
                problem = str(err)
        return Matched(found["depth"], found["mask"], info, up, pending, problem, source)
