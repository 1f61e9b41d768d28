"""The demo: every shipped demo bag evaluated with one estimator, then one summary beside random poses.

The bags (``data/demo_bags/<object>``: rendered views of one demo object with ground-truth /tf) are
found beside the source in a checkout, else in the package's share directory once installed.
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

from idpose_core.evaluation.estimator import ViewSetEstimator
from idpose_core.evaluation.protocol import EvaluationProtocol
from idpose_ros.evaluation.bag_evaluation import BagEvaluation, evaluate_bag
from idpose_ros.evaluation.bag_io import BagError
from idpose_ros.evaluation.bag_report import pooled_summaries, summary_table, write_report

PACKAGE = "idpose_ros"
BAGS_FOLDER = Path("data") / "demo_bags"
SOURCE_BAGS = Path(__file__).resolve().parents[2] / BAGS_FOLDER  # in a checkout
DEMO_PROTOCOL = EvaluationProtocol(samples=1, seed=0, view_counts=(2,))


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


def demo_bags() -> list[Path]:
    """The shipped bags, one per demo object, in name order."""
    return sorted(path for path in demo_bag_folder().iterdir() if (path / "metadata.yaml").is_file())


def demo_summary(evaluations: dict[str, BagEvaluation]) -> str:
    """One row per object and one for all pairs: RotAcc@15/30 and mean rotation error, model vs random poses."""
    rows = {name: (evaluation.aggregates["all"], evaluation.random_aggregates["all"])
            for name, evaluation in evaluations.items()}
    rows["all"] = pooled_summaries(list(evaluations.values()))
    return summary_table(rows)


def run_demo(estimator: ViewSetEstimator, out: Path, say: Callable[[str], None] = print) -> dict[str, BagEvaluation]:
    """Evaluate every demo bag (one n = 2 estimate each), writing each report into ``out/<object>``; ``say`` gets
    each bag's table as it is done."""
    evaluations: dict[str, BagEvaluation] = {}
    for bag in demo_bags():
        say(f"\n== {bag.name} ==")
        evaluations[bag.name] = evaluate_bag(bag, estimator, protocol=DEMO_PROTOCOL)
        say(write_report(out / bag.name, evaluations[bag.name]))
    return evaluations
