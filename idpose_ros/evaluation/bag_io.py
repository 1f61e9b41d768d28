"""rosbag2 files in and out through ``rosbags``: open with clear errors, list topics, write messages.

Both storage formats are read: a bag folder with ``metadata.yaml`` (sqlite3 or mcap inside) or a
bare ``.mcap`` / ``.db3`` file. Messages stay raw CDR bytes here; ``bag_views`` turns them into
numpy.
"""
from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.interfaces import Connection
from rosbags.rosbag2 import CompressionFormat, CompressionMode, ReaderError, StoragePlugin, Writer, WriterError
from rosbags.typesys import Stores, get_typestore

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
STORAGES = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}


class BagError(Exception):
    """A user-facing problem with a bag or a topic in it; the message says what and where."""


@contextmanager
def open_bag(path: str | Path) -> Iterator[AnyReader]:
    """Open a rosbag2 bag (folder or bare .mcap/.db3 file) for reading; BagError when it is not one."""
    path = Path(path)
    if not path.exists():
        raise BagError(f"bag {str(path)!r} does not exist")
    if path.is_file() and path.suffix not in (".mcap", ".db3"):
        raise BagError(f"{str(path)!r} is not a rosbag2 bag: expected a bag folder with metadata.yaml, "
                       "or a .mcap or .db3 file")
    if path.is_dir() and not (path / "metadata.yaml").is_file():
        raise BagError(f"{str(path)!r} is not a rosbag2 bag: the folder has no metadata.yaml")
    reader = AnyReader([path], default_typestore=TYPESTORE)
    try:
        reader.open()
    except (AnyReaderError, ReaderError, OSError, ValueError, KeyError) as err:
        raise BagError(f"{str(path)!r} is not a readable rosbag2 bag: {err}") from None
    try:
        yield reader
    finally:
        reader.close()


def describe_topics(reader: AnyReader) -> str:
    """The bag's topics, one ``name [type] (count)`` per line, for error messages."""
    lines = [f"  {name} [{info.msgtype}] ({info.msgcount} messages)" for name, info in sorted(reader.topics.items())]
    return "\n".join(lines) or "  (the bag has no topics)"


def topic_connections(reader: AnyReader, topic: str, msgtypes: tuple[str, ...]) -> list[Connection]:
    """The connections of ``topic``; BagError listing the bag's topics when it is absent or of another type."""
    connections = [c for c in reader.connections if c.topic == topic]
    if not connections:
        raise BagError(f"topic {topic!r} is not in the bag; it has:\n{describe_topics(reader)}")
    wrong = sorted({c.msgtype for c in connections} - set(msgtypes))
    if wrong:
        raise BagError(f"topic {topic!r} carries {', '.join(wrong)}, expected {' or '.join(msgtypes)}; "
                       f"the bag has:\n{describe_topics(reader)}")
    return connections


class BagWriter:
    """Writes raw CDR messages to a new rosbag2 bag with the ROS 2 Jazzy message definitions.

    ``storage`` is "sqlite3" or "mcap" (mcap chunks are zstd-compressed). Use as a context manager.
    """

    def __init__(self, path: str | Path, storage: str = "mcap"):
        if storage not in STORAGES:
            raise BagError(f"storage must be one of {', '.join(STORAGES)}, got {storage!r}")
        try:
            self._writer = Writer(Path(path), version=Writer.VERSION_LATEST, storage_plugin=STORAGES[storage])
        except WriterError as err:
            raise BagError(str(err)) from None
        if storage == "mcap":
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._connections: dict[str, Connection] = {}

    def __enter__(self) -> BagWriter:
        try:
            self._writer.open()
        except WriterError as err:
            raise BagError(str(err)) from None
        return self

    def __exit__(self, *exc) -> None:
        self._writer.close()

    def write(self, topic: str, msgtype: str, stamp_ns: int, raw: bytes | memoryview) -> None:
        """Append one serialized message, registering the topic on first use."""
        connection = self._connections.get(topic)
        if connection is None:
            connection = self._connections[topic] = self._writer.add_connection(topic, msgtype, typestore=TYPESTORE)
        self._writer.write(connection, int(stamp_ns), bytes(raw))

    def write_message(self, topic: str, msgtype: str, stamp_ns: int, message: object) -> None:
        """Append one rosbags message object, serialized to CDR with the Jazzy typestore."""
        self.write(topic, msgtype, stamp_ns, TYPESTORE.serialize_cdr(message, msgtype))
