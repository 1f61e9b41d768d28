"""`./run demo`: the main job end to end on what ships with the package.

Evaluates every shipped demo bag (``data/demo_bags/<object>``: rendered views of one demo object
with ground-truth /tf) with the embedded demo model, loaded once, n = 2, the `fast` solver preset
(the paper's schedule, `--preset default`, takes about twice as long), prints each bag's table,
then one summary across the demo objects beside the random-pose baseline. The model and solver
options of `evaluate_bag` apply (e.g. `--model-path ~/models/zero123-xl` for real weights).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from idpose_core.zero123 import ModelLoadError
from idpose_ros.bag_io import BagError
from idpose_ros.bag_report import pooled_summaries, summary_table, write_report
from idpose_ros.estimators import add_estimator_arguments, estimator_options, make_estimator
from idpose_ros.evaluate_bag import BagEvaluation, EvaluationProtocol, evaluate_bag
from idpose_ros.replay import ReplayError

DEMO_BAGS = Path(__file__).resolve().parents[1] / "data" / "demo_bags"
PROTOCOL = EvaluationProtocol(samples=1, seed=0, view_counts=(2,))
OUT = Path("demo_output")


def demo_bags() -> list[Path]:
    """The shipped bags, one per demo object, in name order."""
    return sorted(path for path in DEMO_BAGS.iterdir() if (path / "metadata.yaml").is_file())


def demo_summary(evaluations: dict[str, BagEvaluation]) -> str:
    """One row per object and one for all pairs: RotAcc@15/30 and mean rotation error, model vs random poses."""
    rows = {name: (evaluation.aggregates["all"], evaluation.random_aggregates["all"])
            for name, evaluation in evaluations.items()}
    rows["all"] = pooled_summaries(list(evaluations.values()))
    return summary_table(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="demo", description=__doc__.split("\n\n")[1])
    add_estimator_arguments(parser, preset="fast")
    args = parser.parse_args(argv)
    bags = demo_bags()
    print(f"idpose_ros demo: evaluating {len(bags)} shipped bags ({', '.join(b.name for b in bags)}), "
          f"n = 2, {args.preset} preset, one estimate each; reports in ./{OUT}/<object>", flush=True)
    evaluations: dict[str, BagEvaluation] = {}
    estimator = None
    try:
        estimator = make_estimator(estimator_options(args))
        for bag in bags:
            print(f"\n== {bag.name} ==", flush=True)
            evaluations[bag.name] = evaluate_bag(bag, estimator, protocol=PROTOCOL)
            print(write_report(OUT / bag.name, evaluations[bag.name]), flush=True)
    except (BagError, ModelLoadError, ReplayError, ValueError) as err:
        print(f"demo: error: {err}", file=sys.stderr)
        return 2
    finally:
        if estimator is not None:
            estimator.close()
    print("\nAll demo objects (n = 2; random poses: each target camera guessed uniformly on the sphere):\n"
          + demo_summary(evaluations), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
