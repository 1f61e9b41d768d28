"""An mcap file written one flushed message at a time, read back after a kill, and sealed.

``McapLog`` writes unchunked mcap (the ``mcap`` library's writer) and flushes the file after every
message, so a process killed with SIGKILL leaves every message written before the one in progress
in the file (the page cache keeps them; a power cut may lose what the disk had not written yet, as
nothing is fsynced). A killed file lacks its summary and footer: ``scan_mcap`` reads it with the mcap
stream reader up to its last whole record, and ``seal_mcap`` cuts a record left half written and
appends the end records, after which any mcap reader (rosbags included) reads it. Every schema
carries its full ros2msg definition, as rosbags' readers need.
"""
from __future__ import annotations

import contextlib
import fcntl
import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

from mcap.data_stream import RecordBuilder
from mcap.exceptions import EndOfFile, McapError, RecordLengthLimitExceeded
from mcap.records import Channel, DataEnd, Footer, Header, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import MCAP0_MAGIC, CompressionType, IndexType, Writer

from idpose_ros.recording.definitions import message_definition

PROFILE = "ros2"


class RecordingUnreadable(Exception):
    """A file that is not a readable recording of this library; the message says why."""


@dataclass(frozen=True)
class LoggedMessage:
    """One message of the file: its topic, ROS type (``pkg/msg/Name``), log time (ns) and CDR bytes."""

    topic: str
    msgtype: str
    log_time: int
    data: bytes


@dataclass
class Scan:
    """What a file holds: its header's library, every whole message in file order, whether it ends with a
    footer (``sealed``), and the offset after its last whole record (``end``) and the file's size."""

    library: str
    messages: list[LoggedMessage] = field(default_factory=list)
    sealed: bool = False
    end: int = 0
    size: int = 0

    @property
    def cut_bytes(self) -> int:
        """Bytes after the last whole record: a record a kill left half written (0 for a sealed file)."""
        return 0 if self.sealed else self.size - self.end


def hold_lock(stream: BinaryIO) -> bool:
    """Take the exclusive advisory lock of an open file, without waiting; False when another process holds it.
    The system drops a lock when its process ends, however it ends: a held lock means a live writer."""
    try:
        fcntl.flock(stream.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


class McapLog:
    """Appends messages to a new mcap file, flushing after each; ``close`` writes the summary and footer. The
    file stays locked (``hold_lock``) while it is open, so that no one seals it under a live writer."""

    def __init__(self, path: Path, library: str) -> None:
        self.path = path
        self._file: BinaryIO = open(path, "xb")  # noqa: SIM115 (closed by close())
        hold_lock(self._file)
        self._writer = Writer(self._file, use_chunking=False, compression=CompressionType.NONE,
                              index_types=IndexType.NONE)
        self._channels: dict[tuple[str, str], int] = {}
        self._schemas: dict[str, int] = {}
        self._last_time = 0
        self._writer.start(PROFILE, library)
        self._file.flush()

    @property
    def size(self) -> int:
        """Bytes written so far."""
        return self._file.tell()

    def write(self, topic: str, msgtype: str, log_time: int, data: bytes) -> None:
        """Append one CDR message and flush it to the file (log times are kept non-decreasing: rosbags reads an
        unindexed file only in time order)."""
        channel = self._channels.get((topic, msgtype))
        if channel is None:
            schema = self._schemas.get(msgtype)
            if schema is None:
                schema = self._schemas[msgtype] = self._writer.register_schema(
                    msgtype, "ros2msg", message_definition(msgtype).encode())
            channel = self._channels[(topic, msgtype)] = self._writer.register_channel(topic, "cdr", schema)
        self._last_time = max(self._last_time, log_time)
        self._writer.add_message(channel, self._last_time, data, self._last_time)
        self._writer.flush()

    def close(self) -> None:
        """Write the summary and footer and close the file."""
        try:
            self._writer.finish()
        finally:
            self._file.close()

    def abandon(self) -> None:
        """Close the file as it is (after a write failed: it stays readable up to its last whole record)."""
        with contextlib.suppress(OSError):
            self._file.close()


def _records(stream: BinaryIO, size: int) -> Iterator[tuple[object, int]]:
    """(record, offset after it) of every whole record; stops quietly where the file is cut inside a record (one
    longer than the whole file is cut too)."""
    reader = StreamReader(stream, record_size_limit=size)
    try:
        for record in reader.records:
            yield record, stream.tell()
    except (EndOfFile, struct.error, RecordLengthLimitExceeded):
        return


def scan_header(path: Path) -> str:
    """The library named in an mcap file's header; "" when the file is not mcap or is cut inside its header."""
    size = path.stat().st_size
    with open(path, "rb") as stream:
        if stream.read(len(MCAP0_MAGIC)) != MCAP0_MAGIC:
            return ""
        stream.seek(0)
        first = next(_records(stream, size), None)
    return first[0].library if first is not None and isinstance(first[0], Header) else ""


def scan_mcap(path: Path, library_prefix: str) -> Scan:
    """Every whole message of an mcap file written by a library whose name starts with ``library_prefix``;
    RecordingUnreadable when it is not mcap, is another library's, is cut inside its header or holds a
    malformed record."""
    size = path.stat().st_size
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}
    with open(path, "rb") as stream:
        if stream.read(len(MCAP0_MAGIC)) != MCAP0_MAGIC:
            reason = "it is empty" if size == 0 else "it does not start with the mcap magic"
            raise RecordingUnreadable(f"not an mcap file ({reason})")
        stream.seek(0)
        records = _records(stream, size)
        offset = 0
        try:
            first = next(records, None)
            if first is None or not isinstance(first[0], Header):
                raise RecordingUnreadable(f"truncated: the file ends inside its mcap header ({size} bytes)")
            header, end = first
            if header.profile != PROFILE or not header.library.startswith(library_prefix):
                raise RecordingUnreadable(f"foreign: written by {header.library!r} (profile {header.profile!r}), "
                                          f"not by {library_prefix!r}")
            scan = Scan(header.library, end=end, size=size)
            for record, end in records:
                scan.end = offset = end
                if isinstance(record, Schema):
                    schemas[record.id] = record.name
                elif isinstance(record, Channel):
                    channels[record.id] = (record.topic, schemas.get(record.schema_id, ""))
                elif isinstance(record, Message):
                    topic, msgtype = channels[record.channel_id]
                    scan.messages.append(LoggedMessage(topic, msgtype, record.log_time, record.data))
                elif isinstance(record, Footer):
                    scan.sealed = True
        except (McapError, KeyError, UnicodeDecodeError, ValueError) as err:
            raise RecordingUnreadable(f"malformed after byte {offset}: {type(err).__name__}: {err}") from None
    return scan


class RecordingInUse(RecordingUnreadable):
    """A file a live process is still writing: it has no end yet because it is not finished."""


def seal_mcap(path: Path, scan: Scan) -> None:
    """Make a killed file whole: cut the record it left half written and append the end records (no summary; a
    reader scans the messages). Nothing before that record changes; a sealed file is left as it is.
    RecordingInUse when a live writer still holds the file."""
    if scan.sealed:
        return
    builder = RecordBuilder()
    DataEnd(0).write(builder)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
    builder.write(MCAP0_MAGIC)
    with open(path, "r+b") as stream:
        if not hold_lock(stream):
            raise RecordingInUse(f"{path} is being written by a running node: it is sealed when the node stops")
        stream.truncate(scan.end)
        stream.seek(scan.end)
        stream.write(builder.end())
        stream.flush()
        os.fsync(stream.fileno())
    scan.sealed, scan.size = True, path.stat().st_size
