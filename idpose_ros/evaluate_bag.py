"""`evaluate_bag BAG`: the paper's pose metrics for the estimator on the views of a rosbag2 bag.

The views are the images of ``--image-topic``; their true camera poses come from /tf + /tf_static
(``--world-frame`` -> the image's frame, chained and interpolated at the image stamp) or from a
PoseStamped ``--gt-topic``. Seeded picks of 8 views are evaluated on their first 2, 4, 6 and 8
views, the first view being the anchor, either in-process (``--mode offline``) or by replaying the
views to the estimator node over ROS (``--mode replay``). Writes report.json, report.md and
cameras_<sample>.png into ``--out``. A flight recording of the node (``record_dir``) is evaluated on
its own estimates: each is estimated again and scored beside the result the node published. With
``--baselines colmap features`` the classical baselines run
on the same views of every estimate and get their own rows. Offline, ``--save-views DIR`` writes each
used view's mask and the crop the model saw into DIR/views and each estimate's fused object cloud (where
the anchor had depth) into DIR/clouds/<sample>_<n>.ply, and a bag with true target masks gets each view's
mask IoU in the report.

A thin front end: the protocol is ``idpose_core.evaluation``, the bag adapter
``idpose_ros.evaluation.bag_evaluation``, the report ``idpose_ros.evaluation.bag_report``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from idpose_core.evaluation.picks import TooFewViews, usable_view_counts
from idpose_core.evaluation.protocol import EvaluationProtocol
from idpose_core.zero123 import ModelLoadError
from idpose_ros.cli_options import (
    add_baseline_arguments,
    add_estimator_arguments,
    add_ground_truth_arguments,
    add_protocol_arguments,
    estimator_options,
    ground_truth_options,
    protocol_options,
)
from idpose_ros.evaluation.bag_evaluation import evaluate_bag
from idpose_ros.evaluation.bag_io import BagError
from idpose_ros.evaluation.bag_report import write_report
from idpose_ros.evaluation.estimators import make_estimator
from idpose_ros.evaluation.ground_truth import read_views, require_usable, skipped_note
from idpose_ros.evaluation.recording import evaluate_recording
from idpose_ros.evaluation.replay import ReplayError
from idpose_ros.evaluation.view_masks import check_save_views
from idpose_ros.recording.log_format import is_recording


def parse_args(argv: list[str] | None) -> tuple[argparse.Namespace, EvaluationProtocol]:
    parser = argparse.ArgumentParser(prog="evaluate_bag", description=__doc__.split("\n\n")[0].split(": ", 1)[1])
    parser.add_argument("bag", type=Path, help="rosbag2 bag: a folder with metadata.yaml, or a .mcap/.db3 file")
    parser.add_argument("--out", type=Path, default=Path("evaluation"), help="report folder (default ./evaluation)")
    parser.add_argument("--save-views", type=Path, default=None, metavar="DIR",
                        help="offline: write DIR/views/<view id>_mask.png (the mask in the original image) and "
                             "<view id>_crop.png (what the model saw) for every view an estimate used, and "
                             "DIR/clouds/<sample>_<n>.ply, each estimate's fused object cloud (with depth)")
    add_protocol_arguments(parser)
    add_baseline_arguments(parser)
    add_ground_truth_arguments(parser)
    add_estimator_arguments(parser)
    args = parser.parse_args(argv)
    return args, protocol_options(parser, args)


def main(argv: list[str] | None = None) -> int:
    args, protocol = parse_args(argv)
    estimator = None
    try:
        options, ground_truth = estimator_options(args), ground_truth_options(args)
        options.node_values()  # bad solver options, then a bad bag, fail before a model is loaded
        if args.save_views is not None:
            check_save_views(options.mode)
        if is_recording(args.bag):  # the node's recorded estimates, each estimated again
            estimator = make_estimator(options)
            evaluation = evaluate_recording(args.bag, estimator, ground_truth, protocol)
            return finish(args, evaluation)
        views = read_views(args.bag, ground_truth)
        if skipped_note(views):
            print(f"evaluate_bag: {skipped_note(views)}", file=sys.stderr)
        require_usable(views, args.image_topic)
        counts = usable_view_counts(protocol.view_counts, len(views.pool))
        if counts != sorted(set(args.n)):
            print(f"evaluate_bag: {len(views.pool)} usable views: evaluating sets of {', '.join(map(str, counts))} "
                  "views only", file=sys.stderr)
        estimator = make_estimator(options)
        evaluation = evaluate_bag(args.bag, estimator, ground_truth, protocol, views, baselines=args.baselines,
                                  save_views=args.save_views)
    except (BagError, ModelLoadError, ReplayError, TooFewViews, ValueError) as err:
        print(f"evaluate_bag: error: {err}", file=sys.stderr)
        return 2
    finally:
        if estimator is not None:
            estimator.close()
    return finish(args, evaluation)


def finish(args: argparse.Namespace, evaluation) -> int:
    """Write the report, print its table and where it is; the exit code."""
    table = write_report(args.out, evaluation)
    print(table)
    print(f"report: {args.out / 'report.md'}, {args.out / 'report.json'}")
    if args.save_views is not None:
        print(f"views: {args.save_views / 'views'}" + (f", clouds: {args.save_views / 'clouds'}"
                                                      if (args.save_views / "clouds").is_dir() else ""))
    if evaluation.failures:
        total = len(evaluation.failures) + len(evaluation.estimates)
        print(f"evaluate_bag: {len(evaluation.failures)} of {total} estimates failed (listed in the report)",
              file=sys.stderr)
    return 0 if evaluation.estimates else 1


if __name__ == "__main__":
    sys.exit(main())
