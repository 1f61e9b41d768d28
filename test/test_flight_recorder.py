"""The flight recorder's files: what a kill leaves and what is read back, sealing, refusals, rotation.

Real mcap files in a temporary folder, written by ``FlightRecorder`` as the node drives it (views with
their inputs, a reset, a result) and read back with ``read_recording`` and with rosbags (what
evaluate_bag uses). A kill is a file cut where a process killed mid-write leaves it: after a flushed
message, or inside the record being written.
"""
from __future__ import annotations

import os
import re
import threading
from pathlib import Path

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Vector3
from sensor_msgs.msg import Imu

from idpose_core.view_input import ViewInput
from idpose_interfaces.action import EstimatePoses
from idpose_ros import seal_recording
from idpose_ros.evaluation.bag_io import TYPESTORE, BagError, BagWriter, open_bag
from idpose_ros.node.flight_recorder import REFUSED_SUFFIX, FlightRecorder, restored_view
from idpose_ros.recording.log_format import IMAGE_TOPIC, read_recording
from idpose_ros.recording.mcap_log import RecordingUnreadable, seal_mcap
from idpose_ros.view_decoding import ViewMessages, encode_view
from msg_adapters import poses_to_pose_array

SIZE = 48


def view_messages(seed: int, with_gravity: bool = True) -> ViewMessages:
    """A random view with depth, mask, intrinsics and an Imu window as its gravity source."""
    rng = np.random.default_rng(seed)
    view = ViewInput(rng.integers(0, 255, (SIZE, SIZE, 3), dtype=np.uint8),
                     depth=rng.uniform(0.3, 1.0, (SIZE, SIZE)).astype(np.float32),
                     mask=rng.random((SIZE, SIZE)) > 0.5,
                     intrinsics=np.array([[40.0, 0, 24], [0, 40.0, 24], [0, 0, 1]]))
    messages = encode_view(view, Time(sec=100 + seed, nanosec=5), "cam")
    if not with_gravity:
        return messages
    imu = tuple(Imu(linear_acceleration=Vector3(x=0.1 * k, y=-9.8, z=0.0)) for k in range(3))
    return ViewMessages(messages.image, messages.depth, messages.mask, messages.camera_info,
                        np.array([0.01 * seed, -1.0, 0.02]), roi=(1, 2, 30, 40), gravity_source=imu)


class Node:
    """What the node gives the recorder: its buffer and its logger."""

    def __init__(self, directory: Path, max_bytes: int = 10**9, resume: bool = True) -> None:
        self.buffer: list = []
        self.infos: list[str] = []
        self.errors: list[str] = []
        self.recorder = FlightRecorder(str(directory), max_bytes, lambda: list(self.buffer), self.infos.append,
                                       self.errors.append)
        self.buffer = self.recorder.start(resume, {"node": "/test"})

    def keep(self, messages: ViewMessages) -> None:
        """Keep a view as ~/capture does: queued, then written before the answer."""
        view = restored_view(messages)
        self.buffer.append(view)
        self.recorder.view_kept(len(self.buffer), view)
        self.recorder.flush()

    def reset(self) -> None:
        self.recorder.event("reset", dropped=len(self.buffer))
        self.buffer = []


def same_view(a: ViewMessages, b: ViewMessages) -> None:
    assert bytes(a.image.data) == bytes(b.image.data) and a.image.header == b.image.header
    assert bytes(a.depth.data) == bytes(b.depth.data) and bytes(a.mask.data) == bytes(b.mask.data)
    assert a.camera_info.k.tolist() == b.camera_info.k.tolist()
    np.testing.assert_array_equal(a.gravity_up, b.gravity_up)
    assert a.roi == b.roi and len(a.gravity_source) == len(b.gravity_source)


def files(directory: Path) -> list[Path]:
    return sorted(directory.glob("idpose_*.mcap"))


def test_views_since_the_last_reset_come_back_with_their_inputs(tmp_path):
    node = Node(tmp_path)
    node.keep(view_messages(0))
    node.reset()
    kept = [view_messages(seed) for seed in (1, 2, 3)]
    for messages in kept:
        node.keep(messages)
    result = EstimatePoses.Result(run_id=1, poses=poses_to_pose_array(np.stack([np.eye(4)] * 3), "cam",
                                                                      Time(sec=101)), seconds=2.5)
    node.recorder.result(result, {"seed": 0}, node.buffer)
    node.recorder.close()

    recording = read_recording(files(tmp_path)[0])
    assert recording.scan.sealed and [view.index for view in recording.buffered] == [1, 2, 3]
    for recorded, messages in zip(recording.buffered, kept):
        same_view(recorded.messages, messages)
    assert [event["event"] for event in recording.events] == ["session", "carried", "view", "reset", "view", "view",
                                                              "view", "result"]
    (recorded_result,) = recording.results
    assert recorded_result.result.run_id == 1 and recorded_result.settings == {"seed": 0}
    assert recorded_result.view_stamps == [(101 + k) * 10**9 + 5 for k in range(3)]
    with open_bag(files(tmp_path)[0]) as reader:  # rosbags reads the same file
        assert reader.topics[IMAGE_TOPIC].msgcount == 4


def test_a_kill_loses_at_most_the_record_being_written_and_the_file_is_sealed(tmp_path):
    node = Node(tmp_path)
    for seed in range(3):
        node.keep(view_messages(seed))
    path = files(tmp_path)[0]
    whole = path.stat().st_size
    node.keep(view_messages(3))  # killed while writing this view: its image record is cut in half
    node.recorder._writer.abandon()
    with open(path, "r+b") as stream:
        stream.truncate(whole + SIZE * SIZE * 3 // 2)

    restarted = Node(tmp_path)
    assert len(restarted.buffer) == 3, restarted.infos
    for view, seed in zip(restarted.buffer, range(3)):
        same_view(view.received, view_messages(seed))
    assert any("sealed after its last whole record" in line for line in restarted.infos)
    assert read_recording(path).scan.sealed
    with open_bag(path) as reader:  # rosbags reads the sealed file: 3 whole images (the 4th was cut)
        assert reader.topics[IMAGE_TOPIC].msgcount == 3
    restarted.recorder.close()
    carried = read_recording(files(tmp_path)[-1])  # the new session holds the resumed views itself
    assert [view.carried for view in carried.buffered] == [True] * 3


def test_a_truncated_or_foreign_bag_is_refused_and_set_aside(tmp_path):
    node = Node(tmp_path)
    node.keep(view_messages(0))
    node.recorder.close()
    path = files(tmp_path)[0]
    with open(path, "r+b") as stream:
        stream.truncate(20)  # inside its header
    with pytest.raises(RecordingUnreadable, match="truncated"):
        read_recording(path)
    restarted = Node(tmp_path)
    assert restarted.buffer == [] and not path.exists()
    assert (tmp_path / (path.name + REFUSED_SUFFIX)).stat().st_size == 20  # set aside whole, not deleted
    assert "truncated" in restarted.recorder.resumed and "set aside" in restarted.errors[0]
    restarted.recorder.close()

    foreign = tmp_path / "foreign"
    foreign.mkdir()
    with BagWriter(foreign / "bag", storage="mcap") as writer:
        writer.write_message("/x", "std_msgs/msg/String", 1, TYPESTORE.types["std_msgs/msg/String"](data="hi"))
    (written,) = (foreign / "bag").glob("*.mcap")
    os.rename(written, foreign / "idpose_19700101T000000.000000_000.mcap")
    refused = Node(foreign)
    assert refused.buffer == [] and "foreign" in refused.recorder.resumed, refused.recorder.resumed
    refused.recorder.close()


def test_rotation_starts_each_file_with_the_buffered_views(tmp_path):
    node = Node(tmp_path, max_bytes=1_000_000)
    one_view = None
    for seed in range(6):
        node.keep(view_messages(seed))
        one_view = one_view or files(tmp_path)[0].stat().st_size
    node.recorder.max_bytes = 3 * one_view  # rotate after about three views
    for seed in range(6, 12):
        node.keep(view_messages(seed))
    node.recorder.close()
    segments = files(tmp_path)
    assert len(segments) >= 2, [path.stat().st_size for path in segments]
    newest = read_recording(segments[-1])
    assert [view.messages.image.header.stamp.sec for view in newest.buffered] == [100 + seed for seed in range(12)]
    assert newest.session["previous"] == segments[-2].name and newest.buffered[0].carried
    assert Node(tmp_path).buffer[-1].received.image.header.stamp.sec == 111


def test_seal_keeps_every_whole_message(tmp_path):
    node = Node(tmp_path)
    for seed in range(2):
        node.keep(view_messages(seed, with_gravity=False))
    path = files(tmp_path)[0]
    node.recorder._writer.abandon()  # killed between two messages: nothing is cut
    recording = read_recording(path)
    assert not recording.scan.sealed and recording.scan.cut_bytes == 0 and len(recording.buffered) == 2
    seal_mcap(path, recording.scan)
    assert len(read_recording(path).buffered) == 2


def test_seal_recording_makes_a_killed_file_readable_without_the_node_and_leaves_a_live_one(tmp_path, capsys):
    killed = Node(tmp_path / "killed")
    for seed in range(2):
        killed.keep(view_messages(seed, with_gravity=False))
    path = files(tmp_path / "killed")[0]
    whole = path.stat().st_size
    killed.keep(view_messages(2, with_gravity=False))
    killed.recorder._writer.abandon()  # the process dies: its lock goes with it
    with open(path, "r+b") as stream:
        stream.truncate(whole + SIZE * SIZE)  # the third image cut in half
    with pytest.raises(BagError, match="not a readable rosbag2 bag: File end magic is invalid"), open_bag(path):
        pass
    live = Node(tmp_path / "live")
    live.keep(view_messages(0, with_gravity=False))

    assert seal_recording.main([str(tmp_path / "killed"), str(tmp_path / "live")]) == 0
    printed = capsys.readouterr().out
    assert re.search(rf"{re.escape(str(path))}: sealed \(\d+ messages kept, dropping the \d+ bytes of a", printed)
    assert f"{files(tmp_path / 'live')[0]}: in use (" in printed and "running node" in printed
    with open_bag(path) as reader:  # rosbags reads it now: the two whole views
        assert reader.topics[IMAGE_TOPIC].msgcount == 2
    assert not read_recording(files(tmp_path / "live")[0]).scan.sealed, "a live node's file is left alone"
    assert seal_recording.main([str(path)]) == 0 and ": whole" in capsys.readouterr().out
    live.recorder.close()
    assert seal_recording.main([str(tmp_path / "absent")]) == 2
    assert "no such file or folder" in capsys.readouterr().err


def test_keeping_a_view_does_not_wait_for_the_disk_and_flush_does(tmp_path):
    """The image callback only queues a view; ``flush`` (before ~/capture answers) returns once it is in the file.
    A depth image given to a view under the buffer's lock rotates the file without asking the buffer again."""
    lock = threading.Lock()  # the node's buffer lock: ``complete`` holds it while a late input is recorded
    kept: list = []

    def buffered() -> list:
        with lock:
            return list(kept)

    recorder = FlightRecorder(str(tmp_path), 10**9, buffered, print, print)
    recorder.start(False, {"node": "/test"})
    kept.append(restored_view(view_messages(0)))
    with recorder._lock:  # the writer thread is busy (a slow disk): keeping a view must not wait for it
        callback = threading.Thread(target=recorder.view_kept, args=(1, kept[0]))
        callback.start()
        callback.join(timeout=10)
        assert not callback.is_alive(), "keeping a view waits for the writer"
        assert read_recording(files(tmp_path)[0]).views == []
    recorder.flush()
    assert len(read_recording(files(tmp_path)[0]).views) == 1

    recorder.max_bytes = 1  # full: the next write rotates, carrying the buffered view
    with lock:
        late = threading.Thread(target=recorder.view_input, args=(kept[0], "mask", view_messages(0).mask))
        late.start()
        late.join(timeout=10)
        assert not late.is_alive(), "recording a late input under the buffer's lock waits for that lock"
    recorder.flush()
    recorder.close()
    first, second = files(tmp_path)
    assert [view.carried for view in read_recording(second).buffered] == [True]
    assert [event["event"] for event in read_recording(second).events][-1] == "input"
