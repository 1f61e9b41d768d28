"""A replay sends a bag's views as they were recorded (their own encodings), only restamped; views without
messages are encoded losslessly."""
import numpy as np
import pytest
from builtin_interfaces.msg import Time

from idpose_core.view_input import ViewInput
from idpose_ros.dataset.synthetic_bag import DEPTH_TOPIC, INFO_TOPIC, SyntheticBagOptions, make_bag
from idpose_ros.evaluation.bag_views import ExtraTopics, load_views
from idpose_ros.evaluation.ground_truth import GroundTruthOptions, read_views
from idpose_ros.evaluation.replay import REPLAY_FRAME, as_sent
from idpose_ros.view_decoding import MessageView, decode_view

STAMP = Time(sec=42, nanosec=7)


@pytest.fixture(scope="module")
def tabletop_views(tmp_path_factory) -> dict[int, MessageView]:
    path = tmp_path_factory.mktemp("replay") / "bag"
    make_bag(path, SyntheticBagOptions(views=2, seed=3, size=48, scene="tabletop", depth_format="16UC1"))
    extras = ExtraTopics(depth_topic=DEPTH_TOPIC, camera_info_topic=INFO_TOPIC)
    bag = read_views(path, GroundTruthOptions(extras=extras))
    views, problems = load_views(path, GroundTruthOptions().image_topic, {0, 1}, bag, extras)
    assert not problems
    return views


def test_a_bag_view_goes_out_as_recorded_only_restamped(tabletop_views):
    view = tabletop_views[1]
    recorded = view.messages
    assert recorded.depth.encoding == "16UC1"
    sent = as_sent(view, STAMP)
    assert sent.depth.encoding == "16UC1" and sent.image.encoding == recorded.image.encoding
    assert bytes(sent.image.data) == bytes(recorded.image.data) and bytes(sent.depth.data) == bytes(recorded.depth.data)
    for message in (sent.image, sent.depth, sent.camera_info):
        assert (message.header.stamp, message.header.frame_id) == (STAMP, REPLAY_FRAME)
    assert recorded.image.header.frame_id != REPLAY_FRAME, "the recorded messages are left as they were"
    again = decode_view(sent.image, sent.depth, sent.mask, sent.camera_info, sent.gravity_up)
    np.testing.assert_array_equal(again.rgb, view.rgb)
    np.testing.assert_array_equal(again.depth, view.depth)


def test_a_view_without_messages_is_encoded_losslessly(tabletop_views):
    decoded = ViewInput(rgb=tabletop_views[0].rgb, depth=tabletop_views[0].depth)
    sent = as_sent(decoded, STAMP)
    assert sent.depth.encoding == "32FC1" and sent.image.header.frame_id == REPLAY_FRAME
    np.testing.assert_array_equal(decode_view(sent.image, sent.depth).depth, decoded.depth)
