"""The evaluation protocol on one rosbag2 bag: its posed views read, picked, decoded once, estimated and scored.

``evaluate_bag(bag, estimator, ground_truth, protocol)`` returns a ``BagEvaluation``; ``bag_report.write_report``
writes it. Build the estimator once (``estimators.make_estimator``) for many bags.
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from idpose_core.evaluation.estimator import ViewSetEstimator
from idpose_core.evaluation.picks import TooFewViews
from idpose_core.evaluation.protocol import EstimateTask, EvaluationProtocol, plan_tasks
from idpose_core.evaluation.results import Evaluation, evaluate_tasks
from idpose_ros.evaluation.bag_io import BagError
from idpose_ros.evaluation.bag_views import BagViews, load_views
from idpose_ros.evaluation.ground_truth import GroundTruthOptions, read_views, require_usable
from idpose_ros.evaluation.view_masks import ViewMasks, check_save_views, read_true_masks


@dataclass(kw_only=True)
class BagEvaluation(Evaluation):
    """An ``Evaluation`` of one bag, with where its views and truth came from (``report.json`` holds it all), and
    the masks' IoU against the bag's true masks (``ViewMasks.summary``; None without them, or in replay mode)."""

    bag: Path
    ground_truth: GroundTruthOptions
    views: BagViews
    mask_iou: dict[str, Any] | None = None


def plan_bag(views: BagViews, ground_truth: GroundTruthOptions, protocol: EvaluationProtocol
             ) -> list[EstimateTask]:
    """The protocol's estimates on the bag's usable views; BagError when they are too few."""
    require_usable(views, ground_truth.image_topic)
    try:
        return plan_tasks({v: views.world_from_camera[v] for v in views.pool}, protocol, ground_truth.object_center,
                          ground_truth.up)
    except TooFewViews as err:
        raise BagError(str(err)) from None


def evaluate_bag(bag: Path, estimator: ViewSetEstimator, ground_truth: GroundTruthOptions | None = None,
                 protocol: EvaluationProtocol | None = None, views: BagViews | None = None,
                 show_progress: bool = True, baselines: Sequence[str] = (), save_views: Path | None = None
                 ) -> BagEvaluation:
    """Estimate the first n views of each seeded pick of the bag's posed views and score every pair; the
    named classical ``baselines`` run on the same decoded views of every estimate. Where the estimator gives
    its masks (offline), they are scored against the bag's true masks when it has them, and with
    ``save_views`` written there with the crops the model saw (``view_masks``; ValueError in replay mode).

    ``ground_truth`` and ``protocol`` default to ``GroundTruthOptions()`` and ``EvaluationProtocol()``;
    ``views`` are ``read_views(bag, ground_truth)`` when already read. Raises ``BagError`` for an
    unreadable bag, a missing topic or fewer than 2 usable views, ValueError for an unknown baseline,
    and whatever the estimator raises, except that an estimate whose views cannot be prepared (no
    plausible object in one of them, or an image that does not decode) is recorded in ``failures`` and
    the run goes on.
    """
    started = time.perf_counter()
    if save_views is not None:
        check_save_views(estimator.description["mode"])
    gt, protocol = ground_truth or GroundTruthOptions(), protocol or EvaluationProtocol()
    views = views or read_views(bag, gt)
    tasks = plan_bag(views, gt, protocol)
    run = BagEvaluation(**Evaluation.planned(tasks, protocol, estimator, baselines), bag=Path(bag), ground_truth=gt,
                        views=views)
    used = {v for task in tasks for v in task.pick}
    decoded, unusable = load_views(bag, gt.image_topic, used, views, gt.inputs)
    masks = ViewMasks(save_views, read_true_masks(bag, gt.true_mask_topic, views, used, gt.extras.tolerance))
    evaluate_tasks(run, estimator, tasks, decoded, unusable, show_progress, name="evaluate_bag", on_estimate=masks)
    run.mask_iou = masks.summary(gt.true_mask_topic)
    run.seconds = time.perf_counter() - started
    return run
