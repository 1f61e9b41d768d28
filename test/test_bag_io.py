"""Reading real rosbag2 bags (sqlite3 and mcap) into views and ground-truth poses, and bad bags.

Bags are written here with rosbags through make_synthetic_bag (tiny: 3 views of 32 px) or by hand
for the transform-chain cases. No ROS graph is needed: rclpy only (de)serializes messages.
"""
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from builtin_interfaces.msg import Time
from rclpy.serialization import serialize_message
from sensor_msgs.msg import CompressedImage
from std_msgs.msg import Header

from idpose_core.cameras import opengl_to_optical, spherical_to_c2w
from idpose_core.synthetic.scenes import demo_objects, random_camera_spheres
from idpose_core.transforms import rigid_transform
from idpose_ros.dataset.synthetic_bag import (
    IMAGE_TOPIC,
    PERIOD_NS,
    POSE_TOPIC,
    START_NS,
    TRUE_MASK_TOPIC,
    SyntheticBagOptions,
    make_bag,
    write_pose,
    write_rgba_image,
    write_tf,
)
from idpose_ros.evaluation.bag_io import BagError, BagWriter
from idpose_ros.evaluation.bag_views import ExtraTopics, load_views, read_bag_views

SECOND = 1_000_000_000


def quarter_turn_z() -> np.ndarray:
    return np.array([0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)])


@pytest.fixture(scope="module", params=["sqlite3", "mcap"])
def tiny_bag(request, tmp_path_factory):
    """(path, storage, seed): 3 views of the duck, 32 px, written in each storage format."""
    path = tmp_path_factory.mktemp(request.param) / "bag"
    make_bag(path, SyntheticBagOptions(request.param, "demo", None, views=3, seed=7, size=32))
    return path, request.param, 7


def expected_optical_poses(seed: int, views: int) -> np.ndarray:
    """The cameras make_synthetic_bag renders, recomputed from the seed (not read from the bag)."""
    return opengl_to_optical(spherical_to_c2w(random_camera_spheres(np.random.default_rng(seed), views)))


def test_both_storages_give_views_and_chained_tf_ground_truth(tiny_bag):
    path, storage, seed = tiny_bag
    assert (path / "metadata.yaml").is_file()
    assert any(path.glob("*.db3" if storage == "sqlite3" else "*.mcap"))
    bag = read_bag_views(path, IMAGE_TOPIC)
    assert [v.view_id for v in bag.views] == [0, 1, 2] and bag.skipped == {}
    assert [v.stamp for v in bag.views] == [START_NS + i * PERIOD_NS for i in range(3)]
    assert {v.frame_id for v in bag.views} == {"camera_optical_frame"}
    expected = expected_optical_poses(seed, 3)
    for view_id in bag.pool:
        np.testing.assert_allclose(bag.world_from_camera[view_id], expected[view_id], atol=1e-9)


def test_pose_topic_ground_truth_equals_tf_ground_truth(tiny_bag):
    path, _, _ = tiny_bag
    from_tf = read_bag_views(path, IMAGE_TOPIC)
    from_topic = read_bag_views(path, IMAGE_TOPIC, gt_topic=POSE_TOPIC)
    assert from_topic.pool == from_tf.pool == [0, 1, 2]
    for view_id in from_tf.pool:
        np.testing.assert_allclose(from_topic.world_from_camera[view_id], from_tf.world_from_camera[view_id],
                                   atol=1e-12)


def test_images_decode_with_the_mask_in_alpha(tiny_bag):
    path, _, _ = tiny_bag
    views, problems = load_views(path, IMAGE_TOPIC, {0, 2}, read_bag_views(path, IMAGE_TOPIC))
    assert sorted(views) == [0, 2] and problems == {}
    rgb, alpha = views[2].rgb, views[2].alpha
    assert rgb.shape == (32, 32, 3) and alpha.shape == (32, 32)
    assert set(np.unique(alpha)) == {0, 255}
    assert np.all(rgb[alpha == 0] == 255)  # white background
    assert np.any(rgb[alpha == 255] < 200)  # a coloured object


def test_a_tabletop_bag_under_the_training_light_is_the_same_scene_lit_otherwise(tmp_path):
    bags = {light: make_bag(tmp_path / light, SyntheticBagOptions(views=2, seed=3, size=64, scene="tabletop",
                                                                 light=light)) for light in ("random", "training")}
    extras = ExtraTopics(mask_topic=TRUE_MASK_TOPIC)
    views = {light: load_views(bag, IMAGE_TOPIC, {1}, read_bag_views(bag, IMAGE_TOPIC, extras=extras), extras)[0][1]
             for light, bag in bags.items()}
    assert np.array_equal(views["random"].mask, views["training"].mask)  # same layout and camera
    assert np.abs(views["random"].rgb.astype(float) - views["training"].rgb).mean() > 3.0
    with pytest.raises(BagError, match="light must be one of random, training"):
        SyntheticBagOptions(light="sun").check()


def test_a_bare_storage_file_is_a_bag(tiny_bag):
    path, storage, _ = tiny_bag
    (storage_file,) = path.glob("*.db3" if storage == "sqlite3" else "*.mcap")
    assert read_bag_views(storage_file, IMAGE_TOPIC).pool == [0, 1, 2]


def write_chain_bag(path, storage="sqlite3"):
    """world -> base (moving 0..2 m along x over 2 s) -> arm (static) -> camera_optical (static); 3 images.

    Image 0 at t = 1 s (half-way: interpolated), image 1 at t = 2 s (exact sample), image 2 at
    t = 3 s (after the last /tf sample: no ground truth).
    """
    with BagWriter(path, storage) as bag:
        write_tf(bag, 0, [("base", "arm", rigid_transform([0.0, 0.0, 1.0], quarter_turn_z())),
                          ("arm", "camera_optical", rigid_transform([0.5, 0.0, 0.0], [0, 0, 0, 1.0]))], static=True)
        for stamp, x in ((0, 0.0), (2 * SECOND, 2.0)):
            write_tf(bag, stamp, [("world", "base", rigid_transform([x, 0.0, 0.0], [0, 0, 0, 1.0]))])
        pixels = np.full((4, 4, 3), 200, np.uint8)
        for stamp in (SECOND, 2 * SECOND, 3 * SECOND):
            write_rgba_image(bag, "/cam/image", stamp, "camera_optical", pixels, np.ones((4, 4), bool))
        write_pose(bag, "/cam/pose_in_map", SECOND, "map", np.eye(4))


def test_camera_on_a_chain_is_interpolated_at_the_image_stamp(tmp_path):
    write_chain_bag(tmp_path / "chain")
    bag = read_bag_views(tmp_path / "chain", "/cam/image")
    # base at x = 1 (half-way), arm 1 m up turned 90 deg about z, camera 0.5 m along the arm's x = world y
    np.testing.assert_allclose(bag.world_from_camera[0][:3, 3], [1.0, 0.5, 1.0], atol=1e-12)
    np.testing.assert_allclose(bag.world_from_camera[1][:3, 3], [2.0, 0.5, 1.0], atol=1e-12)
    np.testing.assert_allclose(bag.world_from_camera[0][:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    assert bag.pool == [0, 1]
    assert list(bag.skipped) == [2] and "no extrapolation" in bag.skipped[2]


def test_bad_world_frame_or_pose_frame_is_explained(tmp_path):
    write_chain_bag(tmp_path / "chain")
    bag = read_bag_views(tmp_path / "chain", "/cam/image", world_frame="odom")
    assert bag.pool == [] and all("'odom' is not in the transform tree" in r for r in bag.skipped.values())
    with pytest.raises(BagError, match=r"frame 'map', not in the world frame 'world'"):
        read_bag_views(tmp_path / "chain", "/cam/image", gt_topic="/cam/pose_in_map")


def test_missing_topics_list_what_the_bag_has(tmp_path):
    write_chain_bag(tmp_path / "chain")
    with pytest.raises(BagError, match=r"topic '/camera/image_raw' is not in the bag; it has:\n.*/cam/image "
                                       r"\[sensor_msgs/msg/Image\] \(3 messages\)"):
        read_bag_views(tmp_path / "chain", "/camera/image_raw")
    with pytest.raises(BagError, match=r"'/tf' carries tf2_msgs/msg/TFMessage, expected sensor_msgs/msg/Image"):
        read_bag_views(tmp_path / "chain", "/tf")
    with pytest.raises(BagError, match="topic '/gt' is not in the bag"):
        read_bag_views(tmp_path / "chain", "/cam/image", gt_topic="/gt")


def test_pose_topic_matching_skips_views_without_a_pose(tmp_path):
    path = tmp_path / "poses"
    with BagWriter(path, "mcap") as bag:
        for i, stamp in enumerate((SECOND, 2 * SECOND, 3 * SECOND)):
            write_rgba_image(bag, "/img", stamp, "cam", np.zeros((4, 4, 3), np.uint8), np.ones((4, 4), bool))
            if i != 1:
                write_pose(bag, "/gt", stamp + 3_000_000, "world", rigid_transform([i, 0, 0], [0, 0, 0, 1.0]))
    bag = read_bag_views(path, "/img", gt_topic="/gt", gt_tolerance=0.005)
    assert bag.pool == [0, 2] and list(bag.skipped) == [1]
    assert "no /gt pose within 0.005 s" in bag.skipped[1]
    np.testing.assert_allclose(bag.world_from_camera[2][:3, 3], [2, 0, 0])
    assert read_bag_views(path, "/img", gt_topic="/gt", gt_tolerance=0.001).pool == []


def test_compressed_images_and_undecodable_ones(tmp_path):
    path = tmp_path / "compressed"
    rgba = np.zeros((6, 8, 4), np.uint8)
    rgba[..., 2], rgba[2:4, 3:6, 3] = 255, 255  # red, opaque in a small box
    ok, png = cv2.imencode(".png", cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGRA))
    assert ok
    with BagWriter(path, "sqlite3") as bag:
        write_tf(bag, 0, [("world", "cam", np.eye(4))], static=True)
        for stamp, data in ((SECOND, png.tobytes()), (2 * SECOND, b"not an image")):
            message = CompressedImage(header=Header(frame_id="cam", stamp=Time(sec=stamp // SECOND)),
                                      format="bgra8; png compressed bgra8", data=data)
            bag.write("/img/compressed", "sensor_msgs/msg/CompressedImage", stamp, serialize_message(message))
    bag = read_bag_views(path, "/img/compressed")
    assert bag.pool == [0] and "bad image" in bag.skipped[1]
    view = load_views(path, "/img/compressed", {0}, bag)[0][0]
    rgb, alpha = view.rgb, view.alpha
    assert rgb.shape == (6, 8, 3) and np.all(rgb[..., 2] == 255) and alpha.sum() == 6 * 255


def test_scanning_checks_layouts_and_loading_decodes_each_view_once(tmp_path):
    """A png whose header is whole but whose pixels are cut off passes the scan (nothing is decoded there) and is
    reported by load_views, which decodes each requested view once, so that only the estimates holding it fail."""
    path = tmp_path / "cut"
    ok, png = cv2.imencode(".png", np.full((16, 16, 3), 90, np.uint8))
    assert ok
    with BagWriter(path, "mcap") as bag:
        write_tf(bag, 0, [("world", "cam", np.eye(4))], static=True)
        for stamp, data in ((SECOND, png.tobytes()), (2 * SECOND, png.tobytes()[:40])):
            message = CompressedImage(header=Header(frame_id="cam", stamp=Time(sec=stamp // SECOND)), format="png",
                                      data=data)
            bag.write("/img/compressed", "sensor_msgs/msg/CompressedImage", stamp, serialize_message(message))
    views = read_bag_views(path, "/img/compressed")
    assert views.pool == [0, 1] and views.skipped == {}
    decoded, problems = load_views(path, "/img/compressed", {0, 1}, views)
    assert sorted(decoded) == [0] and decoded[0].rgb.shape == (16, 16, 3)
    assert list(problems) == [1] and "does not decode" in problems[1]


def test_paths_that_are_not_bags(tmp_path):
    with pytest.raises(BagError, match="does not exist"):
        read_bag_views(tmp_path / "nowhere", "/img")
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(BagError, match="is not a rosbag2 bag: expected a bag folder"):
        read_bag_views(tmp_path / "notes.txt", "/img")
    with pytest.raises(BagError, match="the folder has no metadata.yaml"):
        read_bag_views(tmp_path, "/img")
    (tmp_path / "broken").mkdir()
    (tmp_path / "broken" / "metadata.yaml").write_text("rosbag2_bagfile_information: {version: 9}\n")
    with pytest.raises(BagError, match="is not a readable rosbag2 bag"):
        read_bag_views(tmp_path / "broken", "/img")
    (tmp_path / "fake.mcap").write_bytes(b"\x00" * 64)
    with pytest.raises(BagError, match="is not a readable rosbag2 bag"):
        read_bag_views(tmp_path / "fake.mcap", "/img")


def test_writer_refuses_to_overwrite(tmp_path):
    with pytest.raises(BagError, match="exists already"):
        BagWriter(tmp_path, "mcap")
    with pytest.raises(BagError, match="storage must be one of"):
        BagWriter(tmp_path / "x", "rosbag1")


def test_a_bag_without_transforms_asks_for_a_gt_topic(tmp_path):
    path = tmp_path / "no_tf"
    with BagWriter(path, "mcap") as bag:
        write_rgba_image(bag, "/img", SECOND, "cam", np.zeros((4, 4, 3), np.uint8), np.ones((4, 4), bool))
    with pytest.raises(BagError, match="no transforms on /tf or /tf_static; give the ground truth with --gt-topic"):
        read_bag_views(path, "/img")


@pytest.mark.parametrize("name", [spec.name for spec in demo_objects()])
def test_the_shipped_demo_bags(name):
    """data/demo_bags/<object>: 12 views of each demo object from make_synthetic_bag (mcap, seed 0, 256 px),
    small enough to ship."""
    path = Path(__file__).resolve().parents[1] / "data" / "demo_bags" / name
    assert sum(f.stat().st_size for f in path.iterdir()) < 5 * 1024 * 1024
    bag = read_bag_views(path, IMAGE_TOPIC)
    assert bag.pool == list(range(12)) and bag.skipped == {}
    expected = expected_optical_poses(0, 12)
    for view_id in bag.pool:
        np.testing.assert_allclose(bag.world_from_camera[view_id], expected[view_id], atol=1e-9)
    view = load_views(path, IMAGE_TOPIC, {0}, bag)[0][0]
    rgb, alpha = view.rgb, view.alpha
    assert rgb.shape == (256, 256, 3) and alpha.max() == 255
