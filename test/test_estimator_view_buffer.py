"""The estimator's view buffer: auto and on-request capture, the bound, clearing."""
import numpy as np
import pytest
from builtin_interfaces.msg import Time

from idpose_core.pipeline import ViewInput
from idpose_ros.view_buffer import CaptureRefused, View, ViewBuffer


def view(index: int) -> View:
    return View(ViewInput(np.full((4, 5, 3), index, np.uint8)), frame_id=f"cam{index}",
                stamp=Time(sec=index), source="Image rgb8")


def test_auto_capture_keeps_views_min_interval_apart_in_order():
    buffer = ViewBuffer(max_views=8)
    kept = [buffer.keep_if_due(view(i), now, min_interval=1.0)
            for i, now in enumerate([10.0, 10.5, 11.0, 11.2, 12.5])]
    assert kept == [1, None, 2, None, 3]
    assert [v.frame_id for v in buffer.snapshot()] == ["cam0", "cam2", "cam4"]


def test_the_bound_refuses_new_views_with_a_reason_and_keeps_the_old_ones():
    buffer = ViewBuffer(max_views=2)
    buffer.keep_if_due(view(0), 0.0, 0.0)
    buffer.keep_if_due(view(1), 1.0, 0.0)
    with pytest.raises(CaptureRefused, match=r"full \(2 views, max_views\).*~/reset"):
        buffer.keep_if_due(view(2), 2.0, 0.0)
    buffer.max_views = 1
    assert len(buffer) == 2, "a lower bound never drops views"
    buffer.max_views = 3
    assert buffer.keep_if_due(view(3), 3.0, 0.0) == 3


def test_on_request_capture_keeps_the_latest_image_once():
    buffer = ViewBuffer(max_views=8)
    with pytest.raises(CaptureRefused, match="no new image"):
        buffer.capture_latest(0.0)
    buffer.observe(view(0))
    buffer.observe(view(1))
    kept, count = buffer.capture_latest(1.0)
    assert (kept.frame_id, count) == ("cam1", 1)
    with pytest.raises(CaptureRefused, match="no new image"):
        buffer.capture_latest(2.0)
    assert [v.frame_id for v in buffer.snapshot()] == ["cam1"]


def test_an_image_kept_automatically_is_not_captured_again():
    buffer = ViewBuffer(max_views=8)
    buffer.keep_if_due(view(0), 0.0, 0.0)
    with pytest.raises(CaptureRefused):
        buffer.capture_latest(0.1)
    assert buffer.keep_if_due(view(1), 0.2, 5.0) is None
    assert buffer.capture_latest(0.3)[1] == 2, "an image skipped by the interval can still be captured"


def test_snapshot_is_a_copy_and_clear_drops_everything():
    buffer = ViewBuffer(max_views=8)
    for i in range(3):
        buffer.keep_if_due(view(i), float(i), 0.0)
    snapshot = buffer.snapshot()
    assert buffer.clear() == 3 and len(buffer) == 0 and len(snapshot) == 3
    assert buffer.keep_if_due(view(9), 0.0, 100.0) == 1, "the interval restarts after a reset"
