"""The demo: every shipped demo bag evaluated with one estimator, then one summary beside random poses.

The bags (``data/demo_bags/<object>``: rendered views of one demo object on white with ground-truth
/tf; ``data/demo_bags/novel/<object>``: the same for held-out objects, which the embedded model never saw;
``data/demo_bags/robot/<name>``: a tabletop scene with aligned depth, intrinsics and an IMU, the
robot's path) are found beside the source in a checkout, else in the package's share directory once
installed.
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

from idpose_core.evaluation.estimator import ViewSetEstimator
from idpose_core.evaluation.protocol import EvaluationProtocol
from idpose_ros.dataset.synthetic_bag import DEPTH_TOPIC, IMU_TOPIC, INFO_TOPIC
from idpose_ros.evaluation.bag_evaluation import BagEvaluation, evaluate_bag
from idpose_ros.evaluation.bag_io import BagError
from idpose_ros.evaluation.bag_report import pooled_summaries, summary_table, write_report
from idpose_ros.evaluation.bag_views import ExtraTopics
from idpose_ros.evaluation.ground_truth import GroundTruthOptions

PACKAGE = "idpose_ros"
BAGS_FOLDER = Path("data") / "demo_bags"
SOURCE_BAGS = Path(__file__).resolve().parents[2] / BAGS_FOLDER  # in a checkout
ROBOT_BAGS = "robot"  # the subfolder of the tabletop bags
NOVEL_BAGS = "novel"  # the subfolder of the bags of objects the embedded model never saw
DEMO_PROTOCOL = EvaluationProtocol(samples=1, seed=0, view_counts=(2,))
# The tabletop bags' inputs as make_synthetic_bag --scene tabletop writes them: depth, intrinsics, gravity.
ROBOT_INPUTS = GroundTruthOptions(extras=ExtraTopics(depth_topic=DEPTH_TOPIC, camera_info_topic=INFO_TOPIC,
                                                     gravity_topic=IMU_TOPIC))


def demo_bag_folder() -> Path:
    """Where the demo bags are: the checkout's ``data/demo_bags``, else the installed package's share directory;
    BagError when neither has them."""
    if SOURCE_BAGS.is_dir():
        return SOURCE_BAGS
    try:
        installed = Path(get_package_share_directory(PACKAGE)) / BAGS_FOLDER
    except PackageNotFoundError:
        installed = None
    if installed is None or not installed.is_dir():
        raise BagError(f"no demo bags: neither {SOURCE_BAGS} nor the share directory of an installed {PACKAGE} "
                       "holds data/demo_bags (build the package with colcon and source its setup script)")
    return installed


def bags_in(folder: Path) -> list[Path]:
    """The bag folders (with metadata.yaml) directly in ``folder``, in name order."""
    return sorted(path for path in folder.iterdir() if (path / "metadata.yaml").is_file()) if folder.is_dir() else []


def demo_bags() -> list[Path]:
    """The shipped bags on white, one per demo object, in name order."""
    return bags_in(demo_bag_folder())


def novel_demo_bags() -> list[Path]:
    """The shipped bags on white of held-out objects (no training run saw them), in name order."""
    return bags_in(demo_bag_folder() / NOVEL_BAGS)


def robot_demo_bags() -> list[Path]:
    """The shipped tabletop bags (depth, intrinsics, gravity), in name order."""
    return bags_in(demo_bag_folder() / ROBOT_BAGS)


def demo_summary(evaluations: dict[str, BagEvaluation]) -> str:
    """One row per object and one for all pairs: RotAcc@15/30 and mean rotation error, model vs random poses."""
    rows = {name: (evaluation.aggregates["all"], evaluation.random_aggregates["all"])
            for name, evaluation in evaluations.items()}
    rows["all"] = pooled_summaries(list(evaluations.values()))
    return summary_table(rows)


def run_demo(estimator: ViewSetEstimator, bags: list[Path], out: Path, options: GroundTruthOptions | None = None,
             say: Callable[[str], None] = print) -> dict[str, BagEvaluation]:
    """Evaluate ``bags`` (one n = 2 estimate each) read with ``options``, writing each report into
    ``out/<bag>``; ``say`` gets each bag's table as it is done."""
    evaluations: dict[str, BagEvaluation] = {}
    for bag in bags:
        say(f"\n== {bag.name} ==")
        evaluations[bag.name] = evaluate_bag(bag, estimator, options, protocol=DEMO_PROTOCOL)
        say(write_report(out / bag.name, evaluations[bag.name]))
    return evaluations
