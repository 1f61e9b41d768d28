"""The evaluate_bag and make_synthetic_bag commands on bad input: a clear message, exit code 2, no traceback.

Every case here fails before a model is loaded or fails to load one, so no model is needed.
"""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from idpose_core.evaluation.picks import TooFewViews, usable_view_counts
from idpose_core.transforms import rigid_transform
from idpose_ros import evaluate_bag, make_synthetic_bag
from idpose_ros.dataset.synthetic_bag import write_rgba_image, write_tf
from idpose_ros.evaluation.bag_io import BagWriter

SECOND = 1_000_000_000
DEMO_BAG = Path(__file__).resolve().parents[1] / "data" / "demo_bags" / "duck"


@pytest.fixture(scope="module")
def one_posed_view_bag(tmp_path_factory):
    """3 images on /img, /tf only around the first one: 1 usable view, 2 without ground truth."""
    path = tmp_path_factory.mktemp("cli") / "bag"
    with BagWriter(path, "sqlite3") as bag:
        for stamp in (SECOND - 1000, SECOND + 1000):
            write_tf(bag, stamp, [("world", "cam", rigid_transform([0.0, -2.0, 0.0], [0.0, 0.0, 0.0, 1.0]))])
        for stamp in (SECOND, 2 * SECOND, 3 * SECOND):
            write_rgba_image(bag, "/img", stamp, "cam", np.zeros((8, 8, 3), np.uint8), np.ones((8, 8), bool))
    return path


def run_main(main, argv, capsys) -> tuple[int, str]:
    code = main(argv)
    return code, capsys.readouterr().err


def test_a_missing_bag(tmp_path, capsys):
    code, err = run_main(evaluate_bag.main, [str(tmp_path / "nowhere"), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "evaluate_bag: error: bag" in err and "does not exist" in err
    assert not (tmp_path / "o").exists()


def test_not_a_bag(tmp_path, capsys):
    (tmp_path / "photo.png").write_bytes(b"\x89PNG")
    code, err = run_main(evaluate_bag.main, [str(tmp_path / "photo.png")], capsys)
    assert code == 2 and "is not a rosbag2 bag" in err


def test_a_topic_not_in_the_bag_lists_the_topics(one_posed_view_bag, capsys):
    code, err = run_main(evaluate_bag.main, [str(one_posed_view_bag), "--image-topic", "/camera/image_raw"], capsys)
    assert code == 2
    assert "topic '/camera/image_raw' is not in the bag; it has:" in err
    assert "/img [sensor_msgs/msg/Image] (3 messages)" in err and "/tf [tf2_msgs/msg/TFMessage]" in err


def test_views_without_ground_truth_are_counted_and_too_few_usable_views_stop(one_posed_view_bag, capsys):
    code, err = run_main(evaluate_bag.main, [str(one_posed_view_bag), "--image-topic", "/img"], capsys)
    assert code == 2
    assert "2 of 3 views skipped" in err
    assert "fewer than 2 usable views (1 of 3 on /img)" in err and "no extrapolation" in err


def test_bad_options_are_refused_by_argparse(one_posed_view_bag, capsys):
    for argv in (["--n", "9"], ["--samples", "0"], ["--mode", "online"]):
        with pytest.raises(SystemExit) as exit_info:
            evaluate_bag.main([str(one_posed_view_bag), *argv])
        assert exit_info.value.code == 2
    code, err = run_main(evaluate_bag.main, [str(one_posed_view_bag), "--solver-param", "refine_lr=-1"], capsys)
    assert code == 2 and "refine_lr" in err


def test_make_synthetic_bag_refuses_an_existing_folder_and_an_unknown_object(tmp_path, capsys):
    code, err = run_main(make_synthetic_bag.main, [str(tmp_path)], capsys)
    assert code == 2 and "exists already" in err
    code, err = run_main(make_synthetic_bag.main, [str(tmp_path / "b"), "--object", "unicorn"], capsys)
    assert code == 2 and "object 'unicorn' is not in the demo set (duck, " in err
    assert not (tmp_path / "b").exists()


@pytest.mark.slow
def test_no_traceback_from_the_command_line(tmp_path):
    """As a user runs it: a separate process, stderr is one clear line."""
    result = subprocess.run([sys.executable, "-m", "idpose_ros.evaluate_bag", str(tmp_path / "missing")],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert "Traceback" not in result.stderr and "does not exist" in result.stderr


def test_small_pools_evaluate_the_view_counts_they_can_hold():
    assert usable_view_counts([8, 2, 4, 6], pool_size=5) == [2, 4]
    assert usable_view_counts([2, 4, 6, 8], pool_size=30) == [2, 4, 6, 8]
    with pytest.raises(TooFewViews, match="only 3 usable views: cannot evaluate sets of 4, 6 views"):
        usable_view_counts([4, 6], pool_size=3)


@pytest.mark.slow
def test_ros2_run_finds_both_commands_and_the_installed_demo_bag(workspace):
    """As `ros2 run idpose_ros evaluate_bag` runs it: the installed script on the installed demo bag."""
    prefix = workspace / "install" / "idpose_ros"
    bag = prefix / "share" / "idpose_ros" / "data" / "demo_bags" / "duck"
    assert (bag / "metadata.yaml").is_file() and (bag / "duck.mcap").is_file()
    for name in ("evaluate_bag", "make_synthetic_bag"):
        assert (prefix / "lib" / "idpose_ros" / name).is_file()
    script = (f". {workspace / 'install' / 'setup.sh'} && "
              f"{prefix / 'lib' / 'idpose_ros' / 'evaluate_bag'} {bag} --image-topic /nope")
    result = subprocess.run(["bash", "-c", script], capture_output=True, text=True, timeout=300)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert "topic '/nope' is not in the bag" in result.stderr
    assert "/camera/image_raw [sensor_msgs/msg/Image]" in result.stderr


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["offline", "replay"])
def test_a_missing_model_is_a_clear_error_in_both_modes(tmp_path, capsys, mode):
    """Offline loads the model here; replay's node fails to load it and says so through /diagnostics."""
    code, err = run_main(evaluate_bag.main, [str(DEMO_BAG), "--mode", mode, "--model-path", str(tmp_path / "none"),
                                             "--out", str(tmp_path / "out")], capsys)
    assert code == 2 and "no such folder or file" in err and "evaluate_bag: error:" in err
    assert not (tmp_path / "out").exists()
