#!/usr/bin/env python3
"""Objects on a cluttered table seen by an RGB-D camera: masks, distance and poses with and without depth.

Renders fresh tabletop bags of the six demo objects with ``make_synthetic_bag --scene tabletop`` (seed
``--seed``, never used in training: the target on a textured table among 2-4 other objects, in a
textured room, random light, aligned 16UC1 depth, the true target mask on /ground_truth/target_mask)
and the same objects' white-background bags from the same seed. Measures, on every view:

- mask IoU against the true mask: GrabCut alone (what a colour image gives), the depth cut
  (support plane + pieces), and depth + GrabCut (the pipeline's "depth" method);
- the object distance from depth against the true camera distance, with the pipeline's statistic
  (mean distance of the visible points + a third of their extent across the view) and with
  the centroid's distance + half the visible depth extent, for comparison;
- then poses with ``evaluate_bag`` (embedded demo model, ``--preset``, n = 2): tabletop with depth and
  camera_info, tabletop without (GrabCut), tabletop with the true masks as an external mask (what
  perfect segmentation would give), and the white-background bags.

Prints the tables and writes bench/results/tabletop/tabletop.json.

    python bench/tabletop.py [--samples 2] [--preset fast] [--threads 2]
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

import numpy as np  # noqa: E402 (after the path setup)
import torch  # noqa: E402

from bench.result_files import result_path  # noqa: E402
from idpose_core.evaluation.protocol import EvaluationProtocol
from idpose_core.metrics import aggregate  # noqa: E402
from idpose_core.preprocessing import grabcut_mask  # noqa: E402
from idpose_core.segmentation import backproject, depth_cut, object_distance  # noqa: E402
from idpose_core.synthetic.scenes import demo_objects  # noqa: E402
from idpose_core.view_input import ViewInput  # noqa: E402
from idpose_ros.dataset.synthetic_bag import (
    DEPTH_TOPIC,
    IMAGE_TOPIC,
    INFO_TOPIC,
    TRUE_MASK_TOPIC,
    SyntheticBagOptions,  # noqa: E402
    make_bag,
)
from idpose_ros.evaluation.bag_evaluation import evaluate_bag
from idpose_ros.evaluation.bag_views import ExtraTopics, load_views, read_bag_views  # noqa: E402
from idpose_ros.evaluation.estimators import EstimatorOptions, make_estimator
from idpose_ros.evaluation.ground_truth import GroundTruthOptions

OUT = result_path("tabletop")
DEPTH = ExtraTopics(depth_topic=DEPTH_TOPIC, camera_info_topic=INFO_TOPIC)
TRUTH = ExtraTopics(depth_topic=DEPTH_TOPIC, camera_info_topic=INFO_TOPIC, mask_topic=TRUE_MASK_TOPIC)
TRUE_MASKS = ExtraTopics(mask_topic=TRUE_MASK_TOPIC)  # segmentation taken out of the question


def iou(mask: np.ndarray, truth: np.ndarray) -> float:
    return float((mask & truth).sum() / max((mask | truth).sum(), 1))


def centroid_plus_half_extent(view, mask: np.ndarray) -> float:
    """The alternative statistic: distance to the visible points' centroid + half their depth extent."""
    points, valid = backproject(view.depth, view.intrinsics)
    visible = points[valid & mask]
    depths = visible[:, 2]
    return float(np.linalg.norm(visible.mean(axis=0)) + 0.5 * np.subtract(*np.percentile(depths, [95, 5])))


def tabletop_views(bag: Path) -> Iterator[tuple[int, ViewInput, np.ndarray, float]]:
    """(view id, the view with its depth and intrinsics, its true target mask, its true distance to the target)
    of every view of a tabletop bag."""
    views = read_bag_views(bag, IMAGE_TOPIC, extras=TRUTH)
    decoded, _ = load_views(bag, IMAGE_TOPIC, set(views.pool), views, TRUTH)
    for view_id in views.pool:
        view = decoded[view_id]
        yield (view_id, replace(view, mask=None), view.mask,
               float(np.linalg.norm(views.world_from_camera[view_id][:3, 3])))


def masks_and_distances(bag: Path) -> list[dict]:
    """Per view of a tabletop bag: the three masks' IoU and both distance statistics beside the truth."""
    rows = []
    for view_id, view, truth, true_distance in tabletop_views(bag):
        cut = depth_cut(view)
        rows.append({"view": view_id, "iou_grabcut": iou(grabcut_mask(view.rgb), truth),
                     "iou_depth": iou(cut.depth_mask, truth), "iou_depth_grabcut": iou(cut.mask, truth),
                     "true_distance": true_distance,
                     "distance": object_distance(view, cut.mask),
                     "distance_centroid_half_extent": centroid_plus_half_extent(view, cut.mask)})
    return rows


def poses(estimator, bags: dict[str, Path], options: GroundTruthOptions, protocol: EvaluationProtocol) -> dict:
    evaluations = [evaluate_bag(bag, estimator, options, protocol) for bag in bags.values()]
    records = [r for e in evaluations for r in e.records]
    methods = [view["mask_method"] for e in evaluations for est in e.estimates for view in est["details"]["views"]]
    return {"aggregates": aggregate(records), "random": aggregate([r for e in evaluations for r in e.random_records]),
            "mask_methods": {m: methods.count(m) for m in sorted(set(methods))},
            "seconds_per_estimate": float(np.mean([est["seconds"] for e in evaluations for est in e.estimates]))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=2, help="evaluate_bag picks per bag (n = 2)")
    parser.add_argument("--views", type=int, default=12, help="views per bag")
    parser.add_argument("--preset", choices=("default", "fast"), default="fast")
    parser.add_argument("--seed", type=int, default=303, help="scene, camera and pick seed of the fresh bags")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    started = time.monotonic()
    names = [spec.name for spec in demo_objects()]
    with tempfile.TemporaryDirectory(prefix="idpose_tabletop_") as folder:
        work = Path(folder)
        tabletop = {name: make_bag(work / f"tabletop_{name}", SyntheticBagOptions(
            object_name=name, views=args.views, seed=args.seed, scene="tabletop")) for name in names}
        plain = {name: make_bag(work / f"plain_{name}", SyntheticBagOptions(
            object_name=name, views=args.views, seed=args.seed)) for name in names}
        per_view = {name: masks_and_distances(bag) for name, bag in tabletop.items()}
        estimator = make_estimator(EstimatorOptions(preset=args.preset))
        protocol = EvaluationProtocol(args.samples, args.seed, (2,))
        pose_runs = {"tabletop, depth + camera_info": poses(estimator, tabletop, GroundTruthOptions(extras=DEPTH),
                                                            protocol),
                     "tabletop, colour only": poses(estimator, tabletop, GroundTruthOptions(), protocol),
                     "tabletop, the true masks": poses(estimator, tabletop, GroundTruthOptions(extras=TRUE_MASKS),
                                                       protocol),
                     "white background (alpha)": poses(estimator, plain, GroundTruthOptions(), protocol)}
    rows = [row for view_rows in per_view.values() for row in view_rows]
    masks = {key: {"mean": float(np.mean([r[key] for r in rows])), "worst": float(np.min([r[key] for r in rows]))}
             for key in ("iou_grabcut", "iou_depth", "iou_depth_grabcut")}
    distance = {key: {"mean_abs_rel": float(np.mean([abs(r[key] / r["true_distance"] - 1) for r in rows])),
                      "worst_abs_rel": float(np.max([abs(r[key] / r["true_distance"] - 1) for r in rows]))}
                for key in ("distance", "distance_centroid_half_extent")}
    result = {"arguments": {k: str(v) for k, v in vars(args).items()}, "views": len(rows), "masks": masks,
              "distance": distance, "poses": pose_runs, "per_view": per_view,
              "minutes": (time.monotonic() - started) / 60}
    print(f"\nMask IoU over {len(rows)} tabletop views:\n| mask | mean IoU | worst IoU |\n|---|---|---|")
    for key, label in (("iou_grabcut", "GrabCut alone"), ("iou_depth", "depth"), ("iou_depth_grabcut",
                                                                                 "depth + GrabCut")):
        print(f"| {label} | {masks[key]['mean']:.3f} | {masks[key]['worst']:.3f} |")
    print("\n| distance statistic | mean relative error | worst |\n|---|---|---|")
    for key, label in (("distance", "mean distance + extent / 3 (used)"),
                       ("distance_centroid_half_extent", "centroid + half depth extent")):
        errors = distance[key]
        print(f"| {label} | {100 * errors['mean_abs_rel']:.1f} % | {100 * errors['worst_abs_rel']:.1f} % |")
    print("\n| views (n = 2) | pairs | RotAcc@15° | RotAcc@30° | mean rot. err. (°) | PosAcc@0.2 | random RotAcc@30° "
          "| masks | s / estimate |\n|---|---|---|---|---|---|---|---|---|")
    for name, run in pose_runs.items():
        model, random = run["aggregates"]["all"], run["random"]["all"]
        methods = ", ".join(f"{method} {count}" for method, count in run["mask_methods"].items())
        print(f"| {name} | {model['pairs']} | {100 * model['rot_acc_15']:.1f} | {100 * model['rot_acc_30']:.1f} | "
              f"{model['mean_rot_err_deg']:.1f} | {100 * model['pos_acc_0.2']:.1f} | "
              f"{100 * random['rot_acc_30']:.1f} | {methods} | {run['seconds_per_estimate']:.1f} |")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out} ({result['minutes']:.0f} min)")


if __name__ == "__main__":
    main()
