"""`evaluate_bag BAG`: the paper's pose metrics for the estimator on the views of a rosbag2 bag.

The views are the images of ``--image-topic``; their true camera poses come from /tf + /tf_static
(``--world-frame`` -> the image's frame, chained and interpolated at the image stamp) or from a
PoseStamped ``--gt-topic``. Seeded picks of 8 views are evaluated on their first 2, 4, 6 and 8
views, the first view being the anchor, either in-process (``--mode offline``) or by replaying the
views to the estimator node over ROS (``--mode replay``). Writes report.json, report.md and
cameras_<sample>.png into ``--out``.

With ``--baselines colmap features`` the classical baselines (``idpose_core.baselines``) run on the same
views of every estimate and get their own rows, with convergence counts and seconds per estimate.

In Python, ``evaluate_bag(bag, estimator, ground_truth, protocol)`` returns a ``BagEvaluation`` and
``bag_report.write_report`` writes it: build the estimator once (``make_estimator``) for many bags.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from idpose_core.baselines import BASELINES, run_baseline
from idpose_core.baselines.scoring import score_baseline
from idpose_core.cameras import c2w_to_spherical
from idpose_core.evaluation import (
    PICK_SIZE,
    VIEW_COUNTS,
    draw_picks,
    object_frame_c2w,
    score_poses,
    world_cameras,
)
from idpose_core.metrics import aggregate, random_pose_errors
from idpose_core.preprocessing import PreprocessingError
from idpose_core.solver import Progress
from idpose_core.zero123 import ModelLoadError
from idpose_ros.bag_io import BagError
from idpose_ros.bag_report import write_report
from idpose_ros.bag_views import (
    BagViews,
    ExtraTopics,
    ViewMessages,
    default_camera_info_topic,
    load_view_messages,
    read_bag_views,
)
from idpose_ros.estimators import (
    NODE_BOUNDS,
    ViewSetEstimator,
    add_estimator_arguments,
    estimator_options,
    make_estimator,
)
from idpose_ros.replay import ReplayError
from idpose_ros.view_inputs import view_input

RANDOM_DRAWS = 200  # random-pose guesses per scored pair: the baseline row of the report


@dataclass(frozen=True)
class GroundTruthOptions:
    """Where a bag's views and their true camera poses are: the image topic, and /tf from ``world_frame``
    (or the PoseStamped ``gt_topic`` matched within ``gt_tolerance`` s); the object's centre and the
    world's up axis in the world frame; the views' other inputs (depth, mask, intrinsics, gravity)."""

    image_topic: str = "/camera/image_raw"
    world_frame: str = "world"
    gt_topic: str | None = None
    gt_tolerance: float = 0.01
    object_center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    extras: ExtraTopics = ExtraTopics()

    @property
    def inputs(self) -> ExtraTopics:
        """``extras`` with the CameraInfo topic beside the image topic unless one is named (optional either way)."""
        topic = self.extras.camera_info_topic or default_camera_info_topic(self.image_topic)
        return replace(self.extras, camera_info_topic=topic)

    @property
    def description(self) -> str:
        return (f"PoseStamped on {self.gt_topic} (within {self.gt_tolerance:g} s)" if self.gt_topic
                else f"/tf + /tf_static ({self.world_frame} -> image frame, at the image stamp)")


@dataclass(frozen=True)
class EvaluationProtocol:
    """``samples`` seeded picks of up to 8 views, each estimated on its first n views for n in ``view_counts``."""

    samples: int = 5
    seed: int = 0
    view_counts: tuple[int, ...] = VIEW_COUNTS


@dataclass
class BagEvaluation:
    """What ``evaluate_bag`` measured on one bag: per-pair records, per-estimate rows, per-sample cameras,
    the random-pose baseline and the classical ``baselines`` on the same pairs (their records and rows by
    name), and what produced them (``report.json`` holds it all)."""

    bag: Path
    ground_truth: GroundTruthOptions
    protocol: EvaluationProtocol
    estimator: dict[str, Any]  # the estimator's description, with its node parameters
    views: BagViews
    picks: list[list[int]]
    view_counts: list[int]  # the requested counts that the usable views allow
    records: list[dict[str, Any]] = field(default_factory=list)
    random_records: list[dict[str, Any]] = field(default_factory=list)
    estimates: list[dict[str, Any]] = field(default_factory=list)
    true_cameras: dict[int, np.ndarray] = field(default_factory=dict)  # sample -> (k, 4, 4) OpenGL c2w
    predicted_cameras: dict[int, np.ndarray] = field(default_factory=dict)  # sample -> largest n's
    baselines: tuple[str, ...] = ()
    baseline_records: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    baseline_estimates: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    failures: list[dict[str, Any]] = field(default_factory=list)  # estimates refused for a view's content
    seconds: float = 0.0

    @property
    def aggregates(self) -> dict[str, dict[str, float | int]]:
        return aggregate(self.records)

    @property
    def random_aggregates(self) -> dict[str, dict[str, float | int]]:
        """The same metrics for random guesses of the target cameras (``pairs`` counts guesses)."""
        return aggregate(self.random_records)

    def add(self, task: EstimateTask, outcome: EstimateOutcome) -> None:
        """Take in one estimate's outcome (the cameras plotted per sample are its largest n's)."""
        self.records.extend(outcome.records)
        self.random_records.extend(outcome.random_records)
        self.estimates.append(outcome.row)
        self.true_cameras[task.sample] = task.true_c2w
        self.predicted_cameras[task.sample] = outcome.predicted_c2w
        for name, (records, row) in outcome.baselines.items():
            self.baseline_records.setdefault(name, []).extend(records)
            self.baseline_estimates.setdefault(name, []).append(row)

    def fail(self, task: EstimateTask, error: Exception) -> None:
        """Record an estimate that could not run on its views (none of its pairs is scored)."""
        self.failures.append({"sample": task.sample, "n": task.n, "views": list(task.pick[:task.n]),
                              "error": str(error)})


def usable_view_counts(requested: Sequence[int], pool_size: int) -> list[int]:
    """The requested view counts a pick from this pool can hold; BagError when none can."""
    pick_size = min(PICK_SIZE, pool_size)
    counts = sorted({n for n in requested if n <= pick_size})
    if not counts:
        raise BagError(f"only {pool_size} usable views: cannot evaluate sets of {', '.join(map(str, requested))} views")
    return counts


def anchor_geometry(true_c2w: np.ndarray) -> tuple[float, float]:
    """(polar angle in degrees, clipped to the node's range so both modes agree; distance) of the anchor."""
    low, high = NODE_BOUNDS["anchor_polar_deg"]
    polar, _, distance = c2w_to_spherical(true_c2w[0])
    return float(np.clip(math.degrees(polar), low, high)), float(distance)


@dataclass(frozen=True)
class EstimateTask:
    """One estimate of the protocol: the first ``n`` views of pick ``sample`` (``pick``: view ids, anchor first),
    with the true cameras of the whole pick (``true_c2w`` (k, 4, 4), OpenGL, object frame); ``index`` is its
    place in the run, which with ``seed`` seeds its random baseline."""

    sample: int
    index: int
    pick: tuple[int, ...]
    n: int
    true_c2w: np.ndarray
    seed: int

    @property
    def baseline_seed(self) -> tuple[int, int, int]:
        """The seed of this estimate's random-pose baseline: the same wherever and whenever it runs."""
        return self.seed, self.index, self.n


@dataclass(frozen=True)
class EstimateOutcome:
    """What one estimate adds to the evaluation: pair records, random-baseline records, the estimate's row,
    the predicted cameras (n, 4, 4), the anchor's true one first, and per classical baseline its (pair
    records, row) on the same views."""

    records: list[dict[str, Any]]
    random_records: list[dict[str, Any]]
    row: dict[str, Any]
    predicted_c2w: np.ndarray
    baselines: dict[str, tuple[list[dict[str, Any]], dict[str, Any]]] = field(default_factory=dict)


def plan_tasks(views: BagViews, ground_truth: GroundTruthOptions, protocol: EvaluationProtocol
               ) -> list[EstimateTask]:
    """The protocol's estimates on these views, in order: each seeded pick with each usable view count."""
    picks = draw_picks(views.pool, protocol.samples, protocol.seed)
    counts = usable_view_counts(protocol.view_counts, len(views.pool))
    cameras = [object_frame_c2w(np.stack([views.world_from_camera[v] for v in pick]), ground_truth.object_center,
                                ground_truth.up) for pick in picks]
    return tasks_for_picks(picks, cameras, counts, protocol.seed)


def tasks_for_picks(picks: Sequence[Sequence[int]], true_cameras: Sequence[np.ndarray], view_counts: Sequence[int],
                    seed: int) -> list[EstimateTask]:
    """Each pick (view ids, anchor first; ``true_cameras``: its (k, 4, 4) OpenGL cameras in the object frame)
    estimated on its first n views for every n of ``view_counts`` it holds, in order; ``seed`` seeds the
    random baselines. Whoever chose the picks (seeded draws from a bag, fixed samples of a data set)."""
    tasks: list[EstimateTask] = []
    for sample, (pick, true_c2w) in enumerate(zip(picks, true_cameras, strict=True)):
        counts = [n for n in view_counts if n <= len(pick)]
        tasks += [EstimateTask(sample, len(tasks) + k, tuple(pick), n, true_c2w, seed) for k, n in enumerate(counts)]
    return tasks


def run_estimate(estimator: ViewSetEstimator, task: EstimateTask, views: Sequence[ViewMessages],
                 progress: Progress | None = None, baselines: Sequence[str] = ()) -> EstimateOutcome:
    """Estimate the task's views (its first n, anchor first) and score them against the truth; then the same for
    each named classical baseline (``idpose_core.baselines.BASELINES``)."""
    true_c2w = task.true_c2w[:task.n]
    anchor_polar_deg, distance = anchor_geometry(true_c2w)
    estimate = estimator(views, anchor_polar_deg, distance, progress)
    records = [{"sample": task.sample, "n": task.n, "anchor_view": task.pick[0], "view": target, **record,
                "score": float(score), "ambiguous": bool(ambiguous), "seconds": estimate.seconds}
               for target, record, score, ambiguous in zip(task.pick[1:task.n], score_poses(estimate.poses, true_c2w),
                                                           estimate.scores, estimate.ambiguous)]
    row = {"sample": task.sample, "n": task.n, "views": list(task.pick[:task.n]), "seconds": estimate.seconds,
           "anchor_polar_deg": anchor_polar_deg, "object_distance": distance, "details": estimate.details}
    predicted = world_cameras(estimate.poses, true_c2w[0])
    return EstimateOutcome(records, random_baseline(true_c2w, task.baseline_seed), row, predicted,
                           {name: classical_baseline(name, task, views) for name in baselines})


def classical_baseline(name: str, task: EstimateTask, views: Sequence[ViewMessages]
                       ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """(pair records, row) of the baseline ``name`` on the task's views (their intrinsics from the anchor's
    CameraInfo when there is one); a view it cannot place gets a random guess (``score_baseline``) seeded by
    the task and the anchor image, so that bags of different objects seen from the same cameras draw
    different guesses."""
    true_c2w = task.true_c2w[:task.n]
    anchor_polar_deg, distance = anchor_geometry(true_c2w)
    inputs = [view_input(view.image, camera_info=view.camera_info) for view in views]
    estimate = run_baseline(name, [(view.rgb, view.alpha) for view in inputs], inputs[0].intrinsics, distance)
    rng = np.random.default_rng([task.seed, task.index, task.n, 1 + list(BASELINES).index(name),
                                 zlib.crc32(bytes(views[0].image.data))])
    records = [{"sample": task.sample, "n": task.n, "anchor_view": task.pick[0], "view": target, **record,
                "seconds": estimate.seconds}
               for target, record in zip(task.pick[1:task.n], score_baseline(
                   estimate, true_c2w, math.radians(anchor_polar_deg), distance, rng))]
    row = {"sample": task.sample, "n": task.n, "views": list(task.pick[:task.n]), "status": estimate.status,
           "registered": [int(v) for v, ok in zip(task.pick, estimate.registered) if ok], "seconds": estimate.seconds}
    return records, row


def random_baseline(true_c2w: np.ndarray, seed: Sequence[int]) -> list[dict[str, Any]]:
    """``RANDOM_DRAWS`` uniform guesses of each of the views 1..n-1 of one estimate (anchor first), scored."""
    n = len(true_c2w)
    rot, pos = random_pose_errors(np.repeat(true_c2w[:1], n - 1, axis=0), true_c2w[1:], RANDOM_DRAWS,
                                  np.random.default_rng(list(seed)))
    return [{"n": n, "rot_err_deg": r, "pos_err": p} for r, p in zip(rot.ravel(), pos.ravel())]


def read_views(bag: Path, ground_truth: GroundTruthOptions) -> BagViews:
    """The bag's views with their ground truth; BagError for an unreadable bag or a missing topic."""
    gt = ground_truth
    return read_bag_views(bag, gt.image_topic, gt.world_frame, gt.gt_topic, gt.gt_tolerance, gt.inputs)


def require_usable(views: BagViews, image_topic: str) -> None:
    """BagError when fewer than 2 views have an image and ground truth."""
    if len(views.pool) < 2:
        reasons = "; ".join(f"view {k}: {r}" for k, r in list(views.skipped.items())[:3])
        raise BagError(f"fewer than 2 usable views ({len(views.pool)} of {len(views.views)} on {image_topic})"
                       + (f"; skipped {reasons}" if reasons else ""))


def evaluate_bag(bag: Path, estimator: ViewSetEstimator, ground_truth: GroundTruthOptions = GroundTruthOptions(),
                 protocol: EvaluationProtocol = EvaluationProtocol(), views: BagViews | None = None,
                 show_progress: bool = True, baselines: Sequence[str] = ()) -> BagEvaluation:
    """Estimate the first n views of each seeded pick of the bag's posed views and score every pair; the
    named classical ``baselines`` run on the same views of every estimate.

    ``views`` are ``read_views(bag, ground_truth)`` when already read. Raises ``BagError`` for an
    unreadable bag, a missing topic or fewer than 2 usable views, ValueError for an unknown baseline,
    and whatever the estimator raises, except that an estimate whose views cannot be prepared
    (``PreprocessingError``: no plausible object in one of them) is recorded in ``failures`` and the run goes on.
    """
    unknown = [name for name in baselines if name not in BASELINES]
    if unknown:
        raise ValueError(f"unknown baseline {unknown[0]!r}: choose from {', '.join(BASELINES)}")
    started = time.perf_counter()
    gt = ground_truth
    views = views or read_views(bag, gt)
    require_usable(views, gt.image_topic)
    tasks = plan_tasks(views, gt, protocol)
    run = BagEvaluation(bag=Path(bag), ground_truth=gt, protocol=protocol,
                        estimator={**estimator.description, "node_parameters": estimator.values}, views=views,
                        picks=list({task.sample: list(task.pick) for task in tasks}.values()),
                        view_counts=sorted({task.n for task in tasks}), baselines=tuple(baselines))
    messages = load_view_messages(bag, gt.image_topic, {v for task in tasks for v in task.pick}, views, gt.inputs)
    with tqdm(total=len(tasks), desc="estimating", unit="set", file=sys.stderr, disable=not show_progress) as bar:
        for task in tasks:
            label = f"sample {task.sample}, {task.n} views"

            def progress(stage: str, done: int, total: int, label: str = label) -> None:
                text = f"{label}: {stage} {100 * done // max(total, 1)} %"
                if text != bar.postfix:
                    bar.set_postfix_str(text)

            bar.set_postfix_str(label)
            try:
                run.add(task, run_estimate(estimator, task, [messages[v] for v in task.pick[:task.n]], progress,
                                           baselines))
            except PreprocessingError as err:  # one implausible view costs its estimate, not the run
                run.fail(task, err)
                bar.write(f"evaluate_bag: {label}: not estimated: {err}", file=sys.stderr)
            bar.update()
    run.seconds = time.perf_counter() - started
    return run


def add_ground_truth_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``GroundTruthOptions`` as command-line options."""
    group = parser.add_argument_group("views and ground truth")
    group.add_argument("--image-topic", default="/camera/image_raw", help="sensor_msgs/Image or CompressedImage")
    group.add_argument("--world-frame", default="world", help="frame of the ground truth (default world)")
    group.add_argument("--gt-topic", default=None,
                       help="geometry_msgs/PoseStamped ground truth (camera optical frame in the world frame), "
                            "matched by stamp; default: /tf + /tf_static")
    group.add_argument("--gt-tolerance", type=float, default=0.01, help="stamp tolerance for --gt-topic (s)")
    group.add_argument("--object-center", type=float, nargs=3, default=(0.0, 0.0, 0.0), metavar=("X", "Y", "Z"),
                       help="object centre in the world frame (default origin)")
    group.add_argument("--up", type=float, nargs=3, default=(0.0, 0.0, 1.0), metavar=("X", "Y", "Z"),
                       help="world up axis (default +z)")
    group = parser.add_argument_group("the views' other inputs (each matched to the image by stamp)")
    group.add_argument("--depth-topic", default=None,
                       help="aligned depth Image (16UC1 mm or 32FC1 m): segments the object, gives its distance")
    group.add_argument("--camera-info-topic", default=None,
                       help="CameraInfo of the colour camera, the nearest in time to each view (needed by depth; "
                            "default: the image topic's camera_info when the bag has it; without, the baselines "
                            "assume a 60 deg field of view)")
    group.add_argument("--mask-topic", default=None, help="object masks (mono8) from a segmentation node")
    group.add_argument("--gravity-topic", default=None,
                       help="sensor_msgs/Imu, or the optical frame's orientation in a z-up frame "
                            "(PoseStamped or QuaternionStamped): each view's roll and elevation")
    group.add_argument("--imu-to-optical", type=float, nargs=4, default=None, metavar=("X", "Y", "Z", "W"),
                       help="rotation from the Imu frame to the optical frame (default: from the bag's transforms)")
    group.add_argument("--input-tolerance", type=float, default=0.02,
                       help="stamp tolerance for these inputs (s, default 0.02)")


def ground_truth_options(args: argparse.Namespace) -> GroundTruthOptions:
    """The options ``add_ground_truth_arguments`` parsed."""
    extras = ExtraTopics(args.depth_topic, args.mask_topic, args.camera_info_topic, args.gravity_topic,
                         tuple(args.imu_to_optical) if args.imu_to_optical else None, args.input_tolerance)
    return GroundTruthOptions(args.image_topic, args.world_frame, args.gt_topic, args.gt_tolerance,
                              tuple(args.object_center), tuple(args.up), extras)


def add_protocol_arguments(parser: argparse.ArgumentParser, samples_help: str = "random picks of 8 views") -> None:
    """The ``EvaluationProtocol`` as command-line options."""
    parser.add_argument("--samples", type=int, default=5, help=f"{samples_help} (default 5)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the picks and of the random-pose baseline")
    parser.add_argument("--n", type=int, nargs="+", default=list(VIEW_COUNTS), help="view counts (default 2 4 6 8)")


def protocol_options(parser: argparse.ArgumentParser, args: argparse.Namespace) -> EvaluationProtocol:
    """The protocol ``add_protocol_arguments`` parsed; a usage error (exit 2) for values out of range."""
    if args.samples < 1:
        parser.error(f"--samples must be at least 1, got {args.samples}")
    if any(not 2 <= n <= PICK_SIZE for n in args.n):
        parser.error(f"--n takes view counts from 2 to {PICK_SIZE}, got {args.n}")
    return EvaluationProtocol(args.samples, args.seed, tuple(args.n))


def parse_args(argv: list[str] | None) -> tuple[argparse.Namespace, EvaluationProtocol]:
    parser = argparse.ArgumentParser(prog="evaluate_bag", description=__doc__.split("\n\n")[0].split(": ", 1)[1])
    parser.add_argument("bag", type=Path, help="rosbag2 bag: a folder with metadata.yaml, or a .mcap/.db3 file")
    parser.add_argument("--out", type=Path, default=Path("evaluation"), help="report folder (default ./evaluation)")
    add_protocol_arguments(parser)
    parser.add_argument("--baselines", nargs="+", choices=tuple(BASELINES), default=[], metavar="NAME",
                        help=f"classical baselines on the same views: {', '.join(BASELINES)}")
    add_ground_truth_arguments(parser)
    add_estimator_arguments(parser)
    args = parser.parse_args(argv)
    return args, protocol_options(parser, args)


def skipped_note(views: BagViews) -> str | None:
    """One line on the views that cannot be evaluated, or None."""
    if not views.skipped:
        return None
    view, reason = next(iter(views.skipped.items()))
    return (f"{len(views.skipped)} of {len(views.views)} views skipped (reasons in report.json), "
            f"e.g. view {view}: {reason}")


def main(argv: list[str] | None = None) -> int:
    args, protocol = parse_args(argv)
    estimator = None
    try:
        options, ground_truth = estimator_options(args), ground_truth_options(args)
        options.node_values()  # bad solver options, then a bad bag, fail before a model is loaded
        views = read_views(args.bag, ground_truth)
        if skipped_note(views):
            print(f"evaluate_bag: {skipped_note(views)}", file=sys.stderr)
        require_usable(views, args.image_topic)
        counts = usable_view_counts(protocol.view_counts, len(views.pool))
        if counts != sorted(set(args.n)):
            print(f"evaluate_bag: {len(views.pool)} usable views: evaluating sets of {', '.join(map(str, counts))} "
                  "views only", file=sys.stderr)
        estimator = make_estimator(options)
        evaluation = evaluate_bag(args.bag, estimator, ground_truth, protocol, views, baselines=args.baselines)
    except (BagError, ModelLoadError, ReplayError, ValueError) as err:
        print(f"evaluate_bag: error: {err}", file=sys.stderr)
        return 2
    finally:
        if estimator is not None:
            estimator.close()
    table = write_report(args.out, evaluation)
    print(table)
    print(f"report: {args.out / 'report.md'}, {args.out / 'report.json'}")
    if evaluation.failures:
        total = len(evaluation.failures) + len(evaluation.estimates)
        print(f"evaluate_bag: {len(evaluation.failures)} of {total} estimates failed (listed in the report)",
              file=sys.stderr)
    return 0 if evaluation.estimates else 1


if __name__ == "__main__":
    sys.exit(main())
