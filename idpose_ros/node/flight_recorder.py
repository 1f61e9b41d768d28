"""The estimator's flight recorder: every kept view, result and event appended to an mcap file in ``record_dir``.

One file per session (``idpose_<start time>_<segment>.mcap``), rotated to a new segment when it
reaches ``record_max_bytes``; a new segment (and a resumed session) begins with the views the
buffer holds, so the newest file alone holds what the buffer held. Every message is flushed as it
is written (``mcap_log``), by one writer thread in call order: keeping a view only queues it (the
image callback does not wait for the disk), while ``result``, ``event`` and ``flush`` return once
everything queued before them is in the file, so whatever the node tells a client about (a captured
view, a reset, a result) is recorded before the answer; at most ``MAX_QUEUED`` writes wait. At
start, the newest file is read: a killed one is sealed (the record it left half written cut off)
and, with ``resume``, its views kept since the last ``~/reset`` are given back to the buffer; one
that cannot be read is renamed ``<name>.refused`` and the node starts empty. A write that fails (a
full disk) stops the recording with one error; nothing here raises into the node, so an estimate
never fails because of the recorder.
"""
from __future__ import annotations

import importlib
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from rclpy.callback_groups import CallbackGroup
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile

from idpose_interfaces.action import EstimatePoses
from idpose_ros.node.view_buffer import View
from idpose_ros.recording.log_format import Recording, RecordingWriter, read_recording
from idpose_ros.recording.mcap_log import RecordingInUse, RecordingUnreadable, seal_mcap
from idpose_ros.view_decoding import ViewMessages, decode_view
from msg_adapters import AdapterError, stamp_nanoseconds

PATTERN = "idpose_*.mcap"
TF_TOPICS = ("/tf", "/tf_static")  # recorded beside the views where tf2_msgs is installed: the ground truth
REFUSED_SUFFIX = ".refused"
MAX_CHAIN = 16  # earlier files looked at when the newest ones end while carrying views over
MAX_QUEUED = 4  # writes waiting for the writer thread; beyond it a call waits (bounded memory on a slow disk)


@dataclass
class WriteCost:
    """What recording kept views cost the writer thread: their count, total bytes and total seconds."""

    views: int = 0
    bytes: int = 0
    seconds: float = 0.0

    def add(self, written: int, seconds: float) -> None:
        self.views, self.bytes, self.seconds = self.views + 1, self.bytes + written, self.seconds + seconds


def recording_name(started: datetime, segment: int) -> str:
    """File name of a segment; names sort in time order."""
    return f"idpose_{started.strftime('%Y%m%dT%H%M%S.%f')}_{segment:03d}.mcap"


def restored_view(recorded: ViewMessages) -> View:
    """A recorded view as the buffer holds it, decoded as the node decodes a captured image; AdapterError when
    it does not decode."""
    image = recorded.image
    source = (f"Image {image.encoding}" if hasattr(image, "encoding") else f"CompressedImage {image.format}")
    return View(decode_view(image, recorded.depth, recorded.mask, recorded.camera_info, recorded.gravity_up,
                            recorded.roi), frame_id=image.header.frame_id, stamp=image.header.stamp,
                source=source, received=recorded)


def subscribe_tf(node: Node, recorder: FlightRecorder, group: CallbackGroup) -> str:
    """Record /tf and /tf_static (transient local, as tf2 publishes it) where tf2_msgs imports; what it does."""
    try:
        message = importlib.import_module("tf2_msgs.msg").TFMessage
    except ImportError:
        return "not recording /tf: tf2_msgs is not installed"
    for topic, qos in ((TF_TOPICS[0], QoSProfile(depth=100)),
                       (TF_TOPICS[1], QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL))):
        node.create_subscription(message, topic, lambda msg, topic=topic: recorder.other(topic, msg), qos,
                                 callback_group=group)
    return "recording /tf and /tf_static"


class FlightRecorder:
    """Records into ``record_dir`` (off when it is empty). ``buffered`` gives the views to carry into a new
    segment; ``log_info`` and ``log_error`` are the node's logger's."""

    def __init__(self, record_dir: str, max_bytes: int, buffered: Callable[[], list[View]],
                 log_info: Callable[[str], None], log_error: Callable[[str], None]) -> None:
        self.directory = Path(record_dir) if record_dir else None
        self.max_bytes = max_bytes
        self._buffered, self._info, self._error = buffered, log_info, log_error
        self._lock = threading.Lock()
        self._writer: RecordingWriter | None = None
        self._started = datetime.now(UTC)
        self._segment = 0
        self.problem = ""  # why the recording stopped
        self.resumed = ""  # what the start found in record_dir
        self.cost = WriteCost()
        self._queue: queue.Queue = queue.Queue(maxsize=MAX_QUEUED)
        self._thread: threading.Thread | None = None
        self._submitting = threading.Lock()  # a write is queued before close's end marker, or not at all

    @property
    def on(self) -> bool:
        """Whether views are being recorded (``received`` messages are worth keeping)."""
        return self._writer is not None

    # ----- start: the last session, then a new file ------------------------------------------------------------------
    def start(self, resume: bool, session: dict[str, Any]) -> list[View]:
        """Read the newest recording (seal it; set it aside if unreadable), open a new one, and with ``resume``
        return the views it held since the last ``~/reset`` (carried into the new file)."""
        if self.directory is None:
            return []
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            previous = self._previous() if resume else None
        except OSError as err:
            self._stop(f"record_dir {str(self.directory)!r}: {err}")
            return []
        views = self._restore(previous) if previous is not None else []
        with self._lock:
            self._open({**session, "resumed_from": previous.path.name if previous else None}, views)
        if self._writer is not None:
            self._thread = threading.Thread(target=self._drain, name="flight_recorder", daemon=True)
            self._thread.start()
        return views

    def _previous(self) -> Recording | None:
        """The newest readable recording whose carried views are whole (sealed), or None; an unreadable newest
        file is set aside."""
        files = sorted(self.directory.glob(PATTERN))
        if not files:
            self.resumed = "no earlier recording"
            return None
        try:
            recording = read_recording(files[-1])
        except (RecordingUnreadable, ValueError) as err:
            self._set_aside(files[-1], str(err))
            return None
        try:
            self._seal(recording)
        except RecordingInUse as err:
            self.resumed = "the newest recording is in use"
            self._error(f"{err}; another node records into {str(self.directory)!r}: nothing resumed from it")
            return None
        chain = 0
        while not recording.carried_complete and chain < MAX_CHAIN:
            earlier = recording.session.get("resumed_from") or recording.session.get("previous")
            if not earlier or not (self.directory / earlier).is_file():
                break
            self._info(f"recording {recording.path.name} ends while carrying views over from {earlier}: "
                       f"resuming from {earlier}")
            try:
                recording, chain = read_recording(self.directory / earlier), chain + 1
            except (RecordingUnreadable, ValueError) as err:
                self._error(f"recording {earlier} cannot be read ({err}): resuming from {recording.path.name}")
                break
        return recording

    def _seal(self, recording: Recording) -> None:
        if recording.scan.sealed:
            return
        cut = recording.scan.cut_bytes
        seal_mcap(recording.path, recording.scan)
        self._info(f"recording {recording.path.name} had no end (the node was killed): sealed after its last whole "
                   f"record" + (f", dropping the {cut} bytes of a record left half written" if cut else ""))

    def _set_aside(self, path: Path, reason: str) -> None:
        target = path.with_name(path.name + REFUSED_SUFFIX)
        counter = 1
        while target.exists():
            target, counter = path.with_name(f"{path.name}{REFUSED_SUFFIX}.{counter}"), counter + 1
        path.rename(target)
        self.resumed = f"refused {path.name}: {reason}; set aside as {target.name}"
        self._error(f"cannot resume from recording {path.name}: {reason}; it is set aside as {target.name} "
                    "(not deleted) and the node starts with no views")

    def _restore(self, recording: Recording) -> list[View]:
        views = []
        for recorded in recording.buffered:
            try:
                views.append(restored_view(recorded.messages))
            except AdapterError as err:
                self._error(f"recording {recording.path.name}: view {recorded.index} does not decode ({err}); "
                            "it is not resumed")
        self.resumed = f"{len(views)} views from {recording.path.name} (kept since its last ~/reset)"
        self._info(f"resumed {self.resumed}")
        return views

    # ----- writing -------------------------------------------------------------------------------------------------
    def _open(self, session: dict[str, Any], views: list[View]) -> None:
        """A new file: its session event, the views carried into it, and the end of carrying (lock held)."""
        path = self.directory / recording_name(self._started, self._segment)
        try:
            self._writer = RecordingWriter(path, {**session, "segment": self._segment, "carry": len(views)})
            for index, view in enumerate(views, start=1):
                self._writer.view(index, view.received, carried=True)
            self._writer.event("carried", views=len(views))
        except OSError as err:
            self._stop(f"writing {path}: {err}")
            return
        self._info(f"recording to {path}")

    def _submit(self, what: Callable[[RecordingWriter], int] | None, carry: int | None = None, wait: bool = False,
                cost: bool = False, snapshot: bool = True) -> None:
        """Queue one write for the writer thread with the buffered views it would carry into a new segment: the
        first ``carry`` (all when None) as the buffer holds them now, or, without ``snapshot`` (a caller holding
        the buffer's lock), those of the write before. With ``wait``, return once it is written (``what`` None:
        once everything before it is)."""
        done = threading.Event() if wait else None
        with self._submitting:
            if self._thread is None or self._writer is None:
                return
            self._queue.put((what, self._buffered()[:carry] if snapshot else None, cost, done))
        if done is not None:
            done.wait()

    def _drain(self) -> None:
        """The writer thread: every queued write in order, until ``close`` queues None."""
        carry: list[View] = []
        while (item := self._queue.get()) is not None:
            what, views, cost, done = item
            carry = carry if views is None else views
            started = time.perf_counter()
            written = self._write(what, carry) if what is not None else 0
            if cost and written:
                self.cost.add(written, time.perf_counter() - started)
            if done is not None:
                done.set()

    def _write(self, what: Callable[[RecordingWriter], int], carry: list[View]) -> int:
        """Run one write (rotating first when the file is full, carrying ``carry``); any failure stops the
        recording."""
        with self._lock:
            if self._writer is None:
                return 0
            try:
                if self._writer.size >= self.max_bytes:
                    self._rotate(carry)
                return what(self._writer) if self._writer is not None else 0
            except Exception as err:  # a full disk or anything else: the node goes on without recording
                self._stop(f"writing {self._writer.path if self._writer else self.directory}: "
                           f"{type(err).__name__}: {err}")
                return 0

    def _rotate(self, views: list[View]) -> None:
        previous = self._writer
        previous.close()
        self._segment += 1
        self._writer = None
        self._info(f"recording {previous.path.name} reached record_max_bytes ({self.max_bytes} bytes): rotating")
        self._open({"previous": previous.path.name}, [view for view in views if view.received])

    def _stop(self, reason: str) -> None:
        if self._writer is not None:
            self._writer.abandon()
            self._writer = None
        self.problem = f"recording stopped: {reason}; the node keeps working without recording"
        self._error(self.problem)

    def view_kept(self, index: int, view: View) -> None:
        """Kept view ``index`` (1 = the anchor), with the messages it was made from: queued (``flush`` waits for
        it)."""
        if view.received is not None:
            self._submit(lambda writer: writer.view(index, view.received), carry=index - 1, cost=True)

    def view_input(self, view: View, kind: str, message: object) -> None:
        """A depth or mask image that reached a kept view after it was kept (called under the buffer's lock):
        queued."""
        self._submit(lambda writer: writer.view_input(stamp_nanoseconds(view.stamp), kind, message), snapshot=False)

    def result(self, result: EstimatePoses.Result, settings: dict[str, Any], views: list[View]) -> None:
        """A published estimate and the parameter values it ran on, written (after its views) when this returns."""
        stamps = [stamp_nanoseconds(view.stamp) for view in views]
        self._submit(lambda writer: writer.result(result, settings, stamps), wait=True)

    def other(self, topic: str, message: object) -> None:
        """A message of another topic (/tf, /tf_static), recorded as received: queued."""
        self._submit(lambda writer: writer.other(topic, message))

    def event(self, name: str, **fields: Any) -> None:
        """``reset``, ``cancel``, ...: a JSON event, written when this returns."""
        self._submit(lambda writer: writer.event(name, **fields), wait=True)

    def flush(self) -> None:
        """Return once everything queued so far is in the file (before answering a client about a kept view)."""
        self._submit(None, wait=True)

    def close(self) -> None:
        """Write what is queued, then the file's summary, and close it (a clean shutdown)."""
        with self._submitting:
            thread, self._thread = self._thread, None
            if thread is not None:
                self._queue.put(None)
        if thread is not None:
            thread.join()
        with self._lock:
            if self._writer is not None:
                try:
                    self._writer.close()
                except OSError as err:
                    self._error(f"recording {self._writer.path.name}: could not write its end: {err}")
                self._writer = None

    def status(self) -> dict[str, str]:
        """Diagnostic values: ``recording`` (off, the file and its size, or why it stopped), ``recording_resumed``
        and the mean cost per recorded view."""
        if self.directory is None:
            return {"recording": "off"}
        with self._lock:
            state = (f"error: {self.problem}" if self.problem else
                     f"{self._writer.path} ({self._writer.size} bytes)" if self._writer else "closed")
        values = {"recording": state, "recording_resumed": self.resumed}
        if self.cost.views:
            values["recording_view_ms"] = f"{1000 * self.cost.seconds / self.cost.views:.2f}"
            values["recording_view_bytes"] = str(self.cost.bytes // self.cost.views)
        return values
