"""The estimator's view buffer: the latest message kept undecoded, auto and on-request capture, the bound, clearing."""
import numpy as np
import pytest
from builtin_interfaces.msg import Time
from sensor_msgs.msg import Image
from std_msgs.msg import Header

from idpose_core.pipeline import ViewInput
from idpose_ros.node.raw_image import RawImage
from idpose_ros.node.view_buffer import CaptureRefused, ImageRefused, View, ViewBuffer


def message(index: int) -> RawImage:
    return RawImage(Image(header=Header(frame_id=f"cam{index}", stamp=Time(sec=index)), encoding="rgb8"), "image")


def decoded(image: RawImage) -> View:
    """A stand-in for the node's decoding: every message becomes a small view."""
    return View(ViewInput(np.zeros((4, 5, 3), np.uint8)), image.frame_id, image.stamp, image.source)


def auto_capture(buffer: ViewBuffer, image: RawImage, now: float, min_interval: float) -> int | None:
    """What the node does with each arriving image in auto mode."""
    buffer.observe(image)
    return buffer.keep_latest(decoded, now)[1] if buffer.due(now, min_interval) else None


def test_auto_capture_keeps_views_min_interval_apart_in_order():
    buffer = ViewBuffer(max_views=8)
    kept = [auto_capture(buffer, message(i), now, min_interval=1.0)
            for i, now in enumerate([10.0, 10.5, 11.0, 11.2, 12.5])]
    assert kept == [1, None, 2, None, 3]
    assert [v.frame_id for v in buffer.snapshot()] == ["cam0", "cam2", "cam4"]
    assert buffer.anchor().frame_id == "cam0" and buffer.snapshot()[1].source == "Image rgb8"


def test_only_the_kept_message_is_decoded():
    buffer = ViewBuffer(max_views=8)
    seen = []
    for index in range(30):
        buffer.observe(message(index))
    view, count = buffer.keep_latest(lambda image: seen.append(image.frame_id) or decoded(image), 1.0)
    assert (view.frame_id, count, seen) == ("cam29", 1, ["cam29"])


def test_the_bound_refuses_new_views_with_a_reason_and_keeps_the_old_ones():
    buffer = ViewBuffer(max_views=2)
    auto_capture(buffer, message(0), 0.0, 0.0)
    auto_capture(buffer, message(1), 1.0, 0.0)
    with pytest.raises(CaptureRefused, match=r"full \(2 views, max_views\).*~/reset"):
        auto_capture(buffer, message(2), 2.0, 0.0)
    buffer.max_views = 1
    assert len(buffer) == 2, "a lower bound never drops views"
    buffer.max_views = 3
    assert buffer.keep_latest(decoded, 3.0)[1] == 3, "the refused image was not handed out"


def test_on_request_capture_keeps_the_latest_image_once():
    buffer = ViewBuffer(max_views=8)
    with pytest.raises(CaptureRefused, match="no new image"):
        buffer.keep_latest(decoded, 0.0)
    buffer.observe(message(0))
    buffer.observe(message(1))
    kept, count = buffer.keep_latest(decoded, 1.0)
    assert (kept.frame_id, count) == ("cam1", 1)
    with pytest.raises(CaptureRefused, match="no new image"):
        buffer.keep_latest(decoded, 2.0)
    assert [v.frame_id for v in buffer.snapshot()] == ["cam1"]


def test_a_refused_image_is_handed_out_once_and_leaves_the_views():
    buffer = ViewBuffer(max_views=8)
    auto_capture(buffer, message(0), 0.0, 0.0)

    def refuse(image: RawImage) -> View:
        raise ImageRefused(f"{image.source}: unreadable")

    buffer.observe(message(1))
    with pytest.raises(ImageRefused, match="Image rgb8: unreadable"):
        buffer.keep_latest(refuse, 1.0)
    with pytest.raises(CaptureRefused, match="no new image"):
        buffer.keep_latest(decoded, 1.0)
    assert len(buffer) == 1 and buffer.due(1.0, 0.5), "a refused image does not count as kept"


def test_an_image_kept_automatically_is_not_captured_again():
    buffer = ViewBuffer(max_views=8)
    auto_capture(buffer, message(0), 0.0, 0.0)
    with pytest.raises(CaptureRefused):
        buffer.keep_latest(decoded, 0.1)
    assert auto_capture(buffer, message(1), 0.2, 5.0) is None
    assert buffer.keep_latest(decoded, 0.3)[1] == 2, "an image skipped by the interval can still be captured"


def test_snapshot_is_a_copy_and_clear_drops_everything():
    buffer = ViewBuffer(max_views=8)
    for i in range(3):
        auto_capture(buffer, message(i), float(i), 0.0)
    buffer.observe(message(7))
    snapshot = buffer.snapshot()
    assert buffer.clear() == 3 and len(buffer) == 0 and len(snapshot) == 3 and buffer.anchor() is None
    with pytest.raises(CaptureRefused, match="no new image"):
        buffer.keep_latest(decoded, 0.0)
    assert auto_capture(buffer, message(9), 0.0, 100.0) == 1, "the interval restarts after a reset"
