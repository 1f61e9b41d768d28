"""`./run demo` (or `ros2 run idpose_ros demo`): the main job end to end on what ships with the package.

Evaluates every shipped demo bag with the embedded model, loaded once, n = 2, the `fast` solver
preset (the paper's schedule, `--preset default`, takes about twice as long), prints each bag's table,
then one summary across the demo objects beside the random-pose baseline; then the same for objects the
model never saw; then the robot's path: a tabletop bag of an object the model never saw, read with its depth,
intrinsics and gravity, posed as the node does by default and by the diffusion estimate alone. The model and solver
options of `evaluate_bag` apply (e.g. `--model-path ~/models/zero123-xl` for real weights).
A thin front end over ``idpose_ros.evaluation.demo_run``.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from functools import partial
from pathlib import Path

from idpose_core.model_loading import load_predictor
from idpose_core.zero123 import ModelLoadError
from idpose_ros.cli_options import add_estimator_arguments, estimator_options
from idpose_ros.evaluation.bag_io import BagError
from idpose_ros.evaluation.demo_run import (
    ROBOT_INPUTS,
    demo_bags,
    demo_summary,
    novel_demo_bags,
    robot_demo_bags,
    run_demo,
)
from idpose_ros.evaluation.estimators import make_estimator
from idpose_ros.evaluation.replay import ReplayError

OUT = Path("demo_output")
DIFFUSION_ONLY = "diffusion_only"  # the subfolder of the tabletop bags' diffusion-only reports


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="demo", description=__doc__.split("\n\n")[1])
    add_estimator_arguments(parser, preset="fast")
    args = parser.parse_args(argv)
    estimator = None
    try:
        bags, novel_bags, robot_bags = demo_bags(), novel_demo_bags(), robot_demo_bags()
        names = ", ".join(b.name for b in bags + novel_bags + robot_bags)
        print(f"idpose_ros demo: evaluating {len(bags) + len(novel_bags) + len(robot_bags)} shipped bags ({names}), "
              f"n = 2, {args.preset} preset, one estimate each; reports in ./{OUT}/<bag>", flush=True)
        options = estimator_options(args)
        predictor = load_predictor(options.model_path, options.device, options.precision)
        estimator = make_estimator(options, predictor)
        say = partial(print, flush=True)
        evaluations = run_demo(estimator, bags, OUT, say=say)
        novel = run_demo(estimator, novel_bags, OUT, say=say)
        robot = run_demo(estimator, robot_bags, OUT, ROBOT_INPUTS, say)
        estimator.close()
        say(f"\nThe same tabletop bags posed by the diffusion estimate alone (depth_poses: refine); reports in "
            f"./{OUT / DIFFUSION_ONLY}/<bag>")
        estimator = make_estimator(dataclasses.replace(options, depth_poses="refine"), predictor)
        diffusion_only = run_demo(estimator, robot_bags, OUT / DIFFUSION_ONLY, ROBOT_INPUTS, say)
    except (BagError, ModelLoadError, ReplayError, ValueError) as err:
        print(f"demo: error: {err}", file=sys.stderr)
        return 2
    finally:
        if estimator is not None:
            estimator.close()
    print("\nAll demo objects (n = 2; random poses: each target camera guessed uniformly on the sphere):\n"
          + demo_summary(evaluations), flush=True)
    if novel:
        print("\nObjects the embedded model never saw (held out of its training; n = 2, one pair each):\n"
              + demo_summary(novel), flush=True)
    if robot:
        print("\nAn object the model never saw, on a tabletop, with depth, intrinsics and gravity (the robot's path; "
              "one pair says little):\n" + demo_summary(robot), flush=True)
        print("\nThe same, the diffusion estimate alone (depth_poses: refine):\n" + demo_summary(diffusion_only),
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
