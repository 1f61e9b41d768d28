"""`evaluate_bag BAG`: the paper's pose metrics for the estimator on the views of a rosbag2 bag.

The views are the images of ``--image-topic``; their true camera poses come from /tf + /tf_static
(``--world-frame`` -> the image's frame, chained and interpolated at the image stamp) or from a
PoseStamped ``--gt-topic``. Seeded picks of 8 views are evaluated on their first 2, 4, 6 and 8
views, the first view being the anchor, either in-process (``--mode offline``) or by replaying the
views to the estimator node over ROS (``--mode replay``). Writes report.json, report.md and
cameras_<sample>.png into ``--out``.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from sensor_msgs.msg import CompressedImage, Image
from tqdm import tqdm

from idpose_core.cameras import c2w_to_spherical
from idpose_core.evaluation import (
    PICK_SIZE,
    VIEW_COUNTS,
    ViewSetEstimate,
    draw_picks,
    object_frame_c2w,
    predicted_c2w,
    relative_from_anchor_frame,
    score_pairs,
)
from idpose_core.metrics import aggregate, random_pose_errors
from idpose_core.model_loading import load_predictor
from idpose_core.pipeline import estimate_view_poses
from idpose_core.predictor import NoisePredictor
from idpose_core.solver import SolverConfig
from idpose_core.zero123 import ModelLoadError
from idpose_ros.bag_io import BagError
from idpose_ros.bag_report import write_report
from idpose_ros.bag_views import BagViews, decode_view, load_view_messages, read_bag_views
from idpose_ros.parameters import SOLVER_PARAMETERS, parameter_table, solver_config
from idpose_ros.replay import ReplayError, ReplayEstimator

ImageMessage = Image | CompressedImage
Progress = Callable[[str, int, int], None]
NODE_BOUNDS = {name: spec["bounds"] for name, _, spec in parameter_table()}
RANDOM_DRAWS = 200  # random-pose guesses per scored pair: the baseline row of the report
DEFAULT_IMAGE_SIZE = next(default for name, default, _ in parameter_table() if name == "image_size")


class ViewSetEstimator(Protocol):
    """Estimates the poses of n views (the first is the anchor) given the anchor's polar angle and distance."""

    model: dict[str, str]  # what estimates: model path, device, precision (and the node, in replay)

    def __call__(self, messages: Sequence[ImageMessage], anchor_polar_deg: float, object_distance: float,
                 progress: Progress | None = None) -> ViewSetEstimate: ...


def node_values(preset: str, variant: str | None, overrides: Sequence[str], image_size: int = DEFAULT_IMAGE_SIZE
                ) -> dict[str, Any]:
    """The node's parameter values that shape an estimate: the solver's (a preset, a variant and
    ``NAME=VALUE`` overrides) and ``image_size``; both modes run on exactly these."""
    config = SolverConfig.preset(preset)
    values = {name: getattr(config, name) for name in SOLVER_PARAMETERS}
    if variant is not None:
        values["variant"] = variant
    for item in overrides:
        name, sep, text = item.partition("=")
        if not sep or name not in SOLVER_PARAMETERS:
            raise ValueError(f"--solver-param {item!r}: expected NAME=VALUE with NAME one of "
                             f"{', '.join(SOLVER_PARAMETERS)}")
        kind = type(values[name])
        try:
            values[name] = kind(text)
        except ValueError:
            raise ValueError(f"--solver-param {item!r}: {name} takes a {kind.__name__}") from None
    solver_config({**values, "anchor_polar_deg": 90.0}).validate()
    low, high = NODE_BOUNDS["image_size"]
    if not low <= image_size <= high:
        raise ValueError(f"--image-size must be in [{low}, {high}] pixels, got {image_size}")
    return {**values, "image_size": image_size}


class OfflineEstimator:
    """Runs the node's pipeline in this process on the same parameters the node would get."""

    def __init__(self, predictor: NoisePredictor, values: dict[str, Any], model: dict[str, str] | None = None):
        self.predictor, self.values = predictor, values
        self.model = model or {"predictor": type(predictor).__name__}

    def __call__(self, messages: Sequence[ImageMessage], anchor_polar_deg: float, object_distance: float,
                 progress: Progress | None = None) -> ViewSetEstimate:
        decoded = [decode_view(message) for message in messages]
        config = solver_config({**self.values, "anchor_polar_deg": anchor_polar_deg})
        start = time.perf_counter()
        result = estimate_view_poses(self.predictor, [rgb for rgb, _ in decoded], [alpha for _, alpha in decoded],
                                     config, math.radians(anchor_polar_deg), object_distance, progress=progress,
                                     image_size=self.values["image_size"])
        solved = result.solver_result
        return ViewSetEstimate(result.poses, np.asarray(solved.scores), np.asarray(solved.ambiguous),
                               time.perf_counter() - start)


@dataclass
class EvaluationRun:
    """Everything the report needs: per-pair records, per-estimate rows, per-sample cameras and the
    random-pose baseline on the same pairs (``RANDOM_DRAWS`` guesses per pair, seeded by ``seed``)."""

    picks: list[list[int]]
    view_counts: list[int]
    seed: int = 0
    records: list[dict[str, Any]] = field(default_factory=list)
    random_records: list[dict[str, Any]] = field(default_factory=list)
    estimates: list[dict[str, Any]] = field(default_factory=list)
    true_cameras: dict[int, np.ndarray] = field(default_factory=dict)  # sample -> (k, 4, 4) OpenGL c2w
    predicted_cameras: dict[int, np.ndarray] = field(default_factory=dict)  # sample -> largest n's

    @property
    def aggregates(self) -> dict[str, dict[str, float | int]]:
        return aggregate(self.records)

    @property
    def random_aggregates(self) -> dict[str, dict[str, float | int]]:
        """The same metrics for random guesses of the target cameras (``pairs`` counts guesses)."""
        return aggregate(self.random_records)

    def add_random_baseline(self, n: int, true_c2w: np.ndarray) -> None:
        """Score ``RANDOM_DRAWS`` uniform guesses of each of the views 1..n-1 of one estimate (anchor first)."""
        rng = np.random.default_rng([self.seed, len(self.estimates), n])
        rot, pos = random_pose_errors(np.repeat(true_c2w[:1], n - 1, axis=0), true_c2w[1:n], RANDOM_DRAWS, rng)
        self.random_records.extend({"n": n, "rot_err_deg": r, "pos_err": p} for r, p in zip(rot.ravel(), pos.ravel()))


def usable_view_counts(requested: Sequence[int], pool_size: int) -> list[int]:
    """The requested view counts a pick from this pool can hold; BagError when none can."""
    pick_size = min(PICK_SIZE, pool_size)
    counts = sorted({n for n in requested if n <= pick_size})
    if not counts:
        raise BagError(f"only {pool_size} usable views: cannot evaluate sets of {', '.join(map(str, requested))} views")
    return counts


def plan_evaluation(bag: BagViews, image_topic: str, samples: int, seed: int, view_counts: Sequence[int]
                    ) -> EvaluationRun:
    """The seeded picks and the view counts to evaluate; BagError when too few views are usable."""
    if len(bag.pool) < 2:
        reasons = "; ".join(f"view {k}: {r}" for k, r in list(bag.skipped.items())[:3])
        raise BagError(f"fewer than 2 usable views ({len(bag.pool)} of {len(bag.views)} on {image_topic})"
                       + (f"; skipped {reasons}" if reasons else ""))
    return EvaluationRun(picks=draw_picks(bag.pool, samples, seed),
                         view_counts=usable_view_counts(view_counts, len(bag.pool)), seed=seed)


def run_evaluation(bag_path: Path, image_topic: str, bag: BagViews, run: EvaluationRun, estimator: ViewSetEstimator,
                   center: Sequence[float], up: Sequence[float], show_progress: bool = True) -> EvaluationRun:
    """Estimate the first n views of each pick of ``run`` and score every (anchor, view) pair into it."""
    picks = run.picks
    messages = load_view_messages(bag_path, image_topic, {v for pick in picks for v in pick})
    low, high = NODE_BOUNDS["anchor_polar_deg"]  # the node's range: both modes clip alike
    with tqdm(total=len(picks) * len(run.view_counts), desc="estimating", unit="set", file=sys.stderr,
              disable=not show_progress) as bar:
        for sample, pick in enumerate(picks):
            true_c2w = object_frame_c2w(np.stack([bag.world_from_camera[v] for v in pick]), center, up)
            anchor_sph = c2w_to_spherical(true_c2w[0])
            anchor_polar_deg = float(np.clip(math.degrees(anchor_sph[0]), low, high))
            distance = float(anchor_sph[2])
            run.true_cameras[sample] = true_c2w
            for n in run.view_counts:
                def progress(stage: str, done: int, total: int, label: str = f"sample {sample}, {n} views") -> None:
                    text = f"{label}: {stage} {100 * done // max(total, 1)} %"
                    if text != bar.postfix:
                        bar.set_postfix_str(text)

                bar.set_postfix_str(f"sample {sample}, {n} views")
                estimate = estimator([messages[v] for v in pick[:n]], anchor_polar_deg, distance, progress)
                rel = relative_from_anchor_frame(estimate.poses, math.radians(anchor_polar_deg), distance)
                for target, record, score, ambiguous in zip(pick[1:n], score_pairs(rel, true_c2w[:n]),
                                                           estimate.scores, estimate.ambiguous):
                    run.records.append({"sample": sample, "n": n, "anchor_view": pick[0], "view": target, **record,
                                        "score": float(score), "ambiguous": bool(ambiguous),
                                        "seconds": estimate.seconds})
                run.add_random_baseline(n, true_c2w)
                run.estimates.append({"sample": sample, "n": n, "views": pick[:n], "seconds": estimate.seconds,
                                      "anchor_polar_deg": anchor_polar_deg, "object_distance": distance})
                run.predicted_cameras[sample] = np.concatenate([true_c2w[:1], predicted_c2w(true_c2w[0], rel)])
                bar.update()
    return run


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="evaluate_bag", description=__doc__.split("\n\n")[0].split(": ", 1)[1])
    parser.add_argument("bag", type=Path, help="rosbag2 bag: a folder with metadata.yaml, or a .mcap/.db3 file")
    parser.add_argument("--out", type=Path, default=Path("evaluation"), help="report folder (default ./evaluation)")
    parser.add_argument("--mode", choices=("offline", "replay"), default="offline",
                        help="offline: solver in this process; replay: through the estimator node over ROS")
    parser.add_argument("--image-topic", default="/camera/image_raw", help="sensor_msgs/Image or CompressedImage")
    parser.add_argument("--world-frame", default="world", help="frame of the ground truth (default world)")
    parser.add_argument("--gt-topic", default=None,
                        help="geometry_msgs/PoseStamped ground truth (camera optical frame in the world frame), "
                             "matched by stamp; default: /tf + /tf_static")
    parser.add_argument("--gt-tolerance", type=float, default=0.01, help="stamp tolerance for --gt-topic (s)")
    parser.add_argument("--object-center", type=float, nargs=3, default=(0.0, 0.0, 0.0), metavar=("X", "Y", "Z"),
                        help="object centre in the world frame (default origin)")
    parser.add_argument("--up", type=float, nargs=3, default=(0.0, 0.0, 1.0), metavar=("X", "Y", "Z"),
                        help="world up axis (default +z)")
    parser.add_argument("--samples", type=int, default=5, help="random picks of 8 views (default 5)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the picks")
    parser.add_argument("--n", type=int, nargs="+", default=list(VIEW_COUNTS), help="view counts (default 2 4 6 8)")
    parser.add_argument("--model-path", default="",
                        help="Zero-1-to-3 diffusers folder or .ckpt (default: the embedded demo model)")
    parser.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto")
    parser.add_argument("--precision", choices=("auto", "float32", "float16", "bfloat16"), default="auto")
    parser.add_argument("--preset", choices=("default", "fast"), default="default", help="solver preset")
    parser.add_argument("--variant", choices=("full", "tr", "naive"), default=None, help="solver variant")
    parser.add_argument("--solver-param", action="append", default=[], metavar="NAME=VALUE",
                        help="override one of the node's solver parameters (repeatable)")
    parser.add_argument("--image-size", type=int, default=DEFAULT_IMAGE_SIZE,
                        help=f"side of the preprocessed views the model sees (default {DEFAULT_IMAGE_SIZE})")
    parser.add_argument("--node", default=None,
                        help="replay: fully qualified name of a running estimator node (default: start one)")
    parser.add_argument("--timeout", type=float, default=3600.0, help="replay: seconds to wait for one estimate")
    args = parser.parse_args(argv)
    if args.samples < 1:
        parser.error(f"--samples must be at least 1, got {args.samples}")
    if any(not 2 <= n <= PICK_SIZE for n in args.n):
        parser.error(f"--n takes view counts from 2 to {PICK_SIZE}, got {args.n}")
    return args


def make_estimator(args: argparse.Namespace, values: dict[str, Any]) -> ViewSetEstimator:
    """The offline estimator (model loaded here) or the replay client (model loaded by the node)."""
    if args.mode == "offline":
        return OfflineEstimator(load_predictor(args.model_path, args.device, args.precision), values,
                                {"model_path": args.model_path, "device": args.device, "precision": args.precision})
    return ReplayEstimator(values, model_path=args.model_path, device=args.device, precision=args.precision,
                           node_name=args.node, timeout=args.timeout)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    started = time.perf_counter()
    try:
        values = node_values(args.preset, args.variant, args.solver_param, args.image_size)
        bag = read_bag_views(args.bag, args.image_topic, args.world_frame, args.gt_topic, args.gt_tolerance)
        if bag.skipped:
            print(f"evaluate_bag: {len(bag.skipped)} of {len(bag.views)} views skipped (reasons in report.json), "
                  f"e.g. view {next(iter(bag.skipped))}: {next(iter(bag.skipped.values()))}", file=sys.stderr)
        run = plan_evaluation(bag, args.image_topic, args.samples, args.seed, args.n)
        if run.view_counts != sorted(set(args.n)):
            print(f"evaluate_bag: {len(bag.pool)} usable views: evaluating sets of "
                  f"{', '.join(map(str, run.view_counts))} views only", file=sys.stderr)
        estimator = make_estimator(args, values)
        try:
            run_evaluation(args.bag, args.image_topic, bag, run, estimator, args.object_center, args.up)
        finally:
            getattr(estimator, "close", lambda: None)()
    except (BagError, ModelLoadError, ReplayError, ValueError) as err:
        print(f"evaluate_bag: error: {err}", file=sys.stderr)
        return 2
    table = write_report(args.out, args, values, estimator.model, bag, run, time.perf_counter() - started)
    print(table)
    print(f"report: {args.out / 'report.md'}, {args.out / 'report.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
