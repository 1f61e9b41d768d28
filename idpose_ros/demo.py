"""`./run demo` (or `ros2 run idpose_ros demo`): the main job end to end on what ships with the package.

Evaluates every shipped demo bag with the embedded demo model, loaded once, n = 2, the `fast` solver
preset (the paper's schedule, `--preset default`, takes about twice as long), prints each bag's table,
then one summary across the demo objects beside the random-pose baseline. The model and solver
options of `evaluate_bag` apply (e.g. `--model-path ~/models/zero123-xl` for real weights).
A thin front end over ``idpose_ros.evaluation.demo_run``.
"""
from __future__ import annotations

import argparse
import sys
from functools import partial
from pathlib import Path

from idpose_core.zero123 import ModelLoadError
from idpose_ros.cli_options import add_estimator_arguments, estimator_options
from idpose_ros.evaluation.bag_io import BagError
from idpose_ros.evaluation.demo_run import demo_bags, demo_summary, run_demo
from idpose_ros.evaluation.estimators import make_estimator
from idpose_ros.evaluation.replay import ReplayError

OUT = Path("demo_output")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="demo", description=__doc__.split("\n\n")[1])
    add_estimator_arguments(parser, preset="fast")
    args = parser.parse_args(argv)
    estimator = None
    try:
        bags = demo_bags()
        print(f"idpose_ros demo: evaluating {len(bags)} shipped bags ({', '.join(b.name for b in bags)}), "
              f"n = 2, {args.preset} preset, one estimate each; reports in ./{OUT}/<object>", flush=True)
        estimator = make_estimator(estimator_options(args))
        evaluations = run_demo(estimator, OUT, partial(print, flush=True))
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
