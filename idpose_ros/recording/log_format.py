"""What a flight recording holds, written and read: views with their inputs, results and events, on mcap topics.

Everything is on topics under ``/idpose_recorder``, as rosbag2 would record them. A kept view is its
image message as received (``image``: Image or CompressedImage), the depth, mask and CameraInfo it was
matched with, its gravity source (the Imu readings of its window on ``imu``, or the orientation on
``camera_orientation``), then a ``view`` event (std_msgs/String, JSON, on ``event``) with its place in
the buffer, world up, its region of interest and the names of its inputs. An event is written after
the messages it speaks for, so a group whose event is missing (a kill while writing it) is ignored
as a whole. Results are the published PoseArray on ``poses``, the action's typed result on
``result`` (``idpose_interfaces/action/EstimatePoses_Result``: per-view estimates, run id, seconds) and
a ``result`` event with the parameter values and the views' stamps. ``~/reset``, cancels, the
session's start and the end of the views it carried over are events too.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseArray, PoseStamped, QuaternionStamped
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, Imu
from std_msgs.msg import String

from idpose_interfaces.action import EstimatePoses
from idpose_ros.recording.definitions import msgtype_of
from idpose_ros.recording.mcap_log import McapLog, Scan, scan_header, scan_mcap
from idpose_ros.view_decoding import ViewMessages
from msg_adapters import stamp_nanoseconds

NAMESPACE = "/idpose_recorder"
LIBRARY_PREFIX = "idpose_ros flight recorder"
FORMAT_VERSION = 1
IMAGE_TOPIC = f"{NAMESPACE}/image"
EVENT_TOPIC = f"{NAMESPACE}/event"
INPUT_TOPICS = {"depth": f"{NAMESPACE}/depth", "mask": f"{NAMESPACE}/mask", "camera_info": f"{NAMESPACE}/camera_info"}
GRAVITY_TOPICS = {"imu": f"{NAMESPACE}/imu", "orientation": f"{NAMESPACE}/camera_orientation"}
POSES_TOPIC, RESULT_TOPIC = f"{NAMESPACE}/poses", f"{NAMESPACE}/result"
TYPES = {"sensor_msgs/msg/Image": Image, "sensor_msgs/msg/CompressedImage": CompressedImage,
         "sensor_msgs/msg/CameraInfo": CameraInfo, "sensor_msgs/msg/Imu": Imu,
         "geometry_msgs/msg/QuaternionStamped": QuaternionStamped, "geometry_msgs/msg/PoseStamped": PoseStamped,
         "geometry_msgs/msg/PoseArray": PoseArray,
         "idpose_interfaces/action/EstimatePoses_Result": EstimatePoses.Result, "std_msgs/msg/String": String}


class RecordingWriter:
    """Writes one recording file: each call appends a group of messages and its event, flushed message by
    message. OSError (a full disk, ...) comes through to the caller."""

    def __init__(self, path: Path, session: dict[str, Any]) -> None:
        self._log = McapLog(path, f"{LIBRARY_PREFIX} {FORMAT_VERSION}")
        self.path = path
        self.event("session", **session)

    @property
    def size(self) -> int:
        return self._log.size

    def _message(self, topic: str, message: object) -> int:
        data = serialize_message(message)
        self._log.write(topic, msgtype_of(message), time.time_ns(), data)
        return len(data)

    def event(self, name: str, **fields: Any) -> int:
        """An event (JSON on the event topic); its bytes."""
        return self._message(EVENT_TOPIC, String(data=json.dumps({"event": name, **fields})))

    def view(self, index: int, messages: ViewMessages, carried: bool = False) -> int:
        """Kept view ``index`` (1 = the anchor) with its inputs; the bytes written."""
        written = self._message(IMAGE_TOPIC, messages.image)
        inputs = {kind: getattr(messages, kind) for kind in INPUT_TOPICS}
        for kind, message in inputs.items():
            if message is not None:
                written += self._message(INPUT_TOPICS[kind], message)
        for message in messages.gravity_source:
            written += self._message(GRAVITY_TOPICS["imu" if isinstance(message, Imu) else "orientation"], message)
        up = None if messages.gravity_up is None else [float(x) for x in messages.gravity_up]
        header = messages.image.header
        return written + self.event(
            "view", index=index, stamp=stamp_nanoseconds(header.stamp), frame_id=header.frame_id,
            inputs=sorted(kind for kind, message in inputs.items() if message is not None), gravity_up=up,
            gravity_readings=len(messages.gravity_source), roi=None if messages.roi is None else list(messages.roi),
            carried=carried)

    def view_input(self, index: int, kind: str, message: Image) -> int:
        """A depth or mask image that reached view ``index`` after it was kept."""
        return self._message(INPUT_TOPICS[kind], message) + self.event("input", view=index, kind=kind)

    def result(self, result: EstimatePoses.Result, settings: dict[str, Any], view_stamps: list[int]) -> int:
        """A published estimate: its PoseArray, the typed result, the parameter values it ran on."""
        written = self._message(POSES_TOPIC, result.poses) + self._message(RESULT_TOPIC, result)
        return written + self.event("result", run_id=result.run_id, seconds=float(result.seconds),
                                    settings=settings, view_stamps=view_stamps)

    def other(self, topic: str, message: object) -> int:
        """A message of another topic, as received (e.g. /tf for the ground truth): in no group."""
        return self._message(topic, message)

    def close(self) -> None:
        self._log.close()

    def abandon(self) -> None:
        self._log.abandon()


@dataclass
class RecordedView:
    """A kept view as recorded: its place in the buffer (1 = the anchor), messages and whether it was carried
    over from an earlier file."""

    index: int
    messages: ViewMessages
    carried: bool = False

    @property
    def stamp(self) -> int:
        return stamp_nanoseconds(self.messages.image.header.stamp)


@dataclass
class RecordedResult:
    """A published estimate as recorded: the typed result, the parameter values and the views' stamps."""

    result: EstimatePoses.Result
    settings: dict[str, Any]
    view_stamps: list[int]


@dataclass
class Recording:
    """A recording read back: its session event, every event in order, the views kept, the results, and the views
    the buffer held at its end (``buffered``: those kept since the last ``~/reset``, with inputs that reached
    them later). ``carried_complete`` is False when the file ends while it still carried views over."""

    path: Path
    scan: Scan
    session: dict[str, Any] = field(default_factory=dict)
    events: list[dict[str, Any]] = field(default_factory=list)
    views: list[RecordedView] = field(default_factory=list)
    results: list[RecordedResult] = field(default_factory=list)
    buffered: list[RecordedView] = field(default_factory=list)
    carried_complete: bool = True


def _view(event: dict[str, Any], group: dict[str, list[object]]) -> RecordedView:
    def first(topic: str) -> object | None:
        return group.get(topic, [None])[0]

    up = event["gravity_up"]
    messages = ViewMessages(
        first(IMAGE_TOPIC), **{kind: first(topic) for kind, topic in INPUT_TOPICS.items()},
        gravity_up=None if up is None else np.asarray(up, dtype=np.float64),
        roi=None if event["roi"] is None else tuple(event["roi"]),
        gravity_source=tuple(group.get(GRAVITY_TOPICS["imu"], []) + group.get(GRAVITY_TOPICS["orientation"], [])))
    return RecordedView(event["index"], messages, event["carried"])


def read_recording(path: Path) -> Recording:
    """Every whole group of a recording (a cut-off last group is left out); RecordingUnreadable for a file that is
    not one, ValueError for a group that does not make sense (the reason names it)."""
    scan = scan_mcap(path, LIBRARY_PREFIX)
    recording = Recording(path, scan)
    group: dict[str, list[object]] = {}
    for message in scan.messages:
        if not message.topic.startswith(NAMESPACE + "/") or message.msgtype not in TYPES:
            continue  # e.g. /tf, recorded for the ground truth
        decoded = deserialize_message(message.data, TYPES[message.msgtype])
        if message.topic != EVENT_TOPIC:
            group.setdefault(message.topic, []).append(decoded)
            continue
        event = json.loads(decoded.data)
        recording.events.append(event)
        name = event.get("event")
        if name == "session":
            recording.session = event
            recording.carried_complete = not event.get("carry")
        elif name == "carried":
            recording.carried_complete = True
        elif name == "view":
            if IMAGE_TOPIC not in group:
                raise ValueError(f"{path.name}: view event {event.get('index')} without its image")
            view = _view(event, group)
            recording.views.append(view)
            recording.buffered.append(view)
        elif name == "input":
            kind, index = event["kind"], event["view"]
            if 1 <= index <= len(recording.buffered) and INPUT_TOPICS.get(kind) in group:
                view = recording.buffered[index - 1]
                view.messages = replace(view.messages, **{kind: group[INPUT_TOPICS[kind]][0]})
        elif name == "reset":
            recording.buffered = []
        elif name == "result":
            recording.results.append(RecordedResult(group[RESULT_TOPIC][0], event["settings"], event["view_stamps"]))
        group = {}
    return recording


def is_recording(path: Path) -> bool:
    """Whether ``path`` is an mcap file the flight recorder wrote."""
    path = Path(path)
    return path.is_file() and path.suffix == ".mcap" and scan_header(path).startswith(LIBRARY_PREFIX)


def recordings_in(folder: Path) -> list[Path]:
    """The flight recordings under ``folder`` (any depth: a record_dir, or a folder of them), sorted by path."""
    return sorted(path for path in Path(folder).rglob("*.mcap") if is_recording(path))
