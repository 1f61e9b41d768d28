"""The goal server's own rules, without a node: which views a goal estimates and on which parameter values.
A goal's run, feedback and cancel go through a real node in test_estimator_action.py."""
from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from std_msgs.msg import Header

from idpose_core.solver import SolverConfig
from idpose_interfaces.action import EstimatePoses
from idpose_ros.node.estimate_run import EstimateRefused
from idpose_ros.node.goal_server import goal_values, goal_views
from idpose_ros.node.parameters import SOLVER_PARAMETERS
from idpose_ros.node.raw_image import RawImage
from idpose_ros.node.view_buffer import ImageRefused, View
from msg_adapters import AdapterError, array_to_image

Result = EstimatePoses.Result


class DecodingEstimator:
    """What ``goal_views`` is given: the buffered views, and an image decoded into a view (the node's
    ``ViewIntake.prepare`` also matches depth and gravity; here the decode alone, refused as the node refuses)."""

    def __init__(self, buffered: list[View]) -> None:
        self.buffered, self.prepared = buffered, []

    def buffered_views(self) -> list[View]:
        return list(self.buffered)

    def prepare(self, image: RawImage) -> View:
        try:
            pixels = image.decode(max_pixels=1 << 20)
        except AdapterError as exc:
            raise ImageRefused(f"{image.source} on {image.topic}: {exc}") from exc
        self.prepared.append(image.topic)
        return View(pixels, image.frame_id, image.stamp, image.source)


def image(seconds: int, encoding: str = "rgb8") -> Any:
    rgb = np.full((40, 40, 3), 120, np.uint8)
    message = array_to_image(rgb, "rgb8", Header(frame_id="cam", stamp=Time(sec=seconds)))
    message.encoding = encoding
    return message


def test_a_goal_without_images_estimates_the_buffered_views():
    buffered = DecodingEstimator([]).prepare(RawImage(image(1), "image"))
    estimator = DecodingEstimator([buffered, buffered])
    views = goal_views(EstimatePoses.Goal(), estimator.buffered_views, estimator.prepare)
    assert views == [buffered, buffered] and estimator.prepared == []


def test_a_goal_s_images_become_views_in_order_and_a_bad_one_is_named():
    estimator = DecodingEstimator([])
    views = goal_views(EstimatePoses.Goal(images=[image(1), image(2), image(3)]), estimator.buffered_views,
                       estimator.prepare)
    assert [view.stamp.sec for view in views] == [1, 2, 3]
    assert estimator.prepared == ["goal image 0", "goal image 1", "goal image 2"]
    with pytest.raises(EstimateRefused, match="at least 2 images") as one:
        goal_views(EstimatePoses.Goal(images=[image(1)]), estimator.buffered_views, estimator.prepare)
    assert one.value.code == Result.INVALID_GOAL
    with pytest.raises(EstimateRefused, match="goal image 1") as bad:
        goal_views(EstimatePoses.Goal(images=[image(1), image(2, encoding="yuv_nonsense")]),
                   estimator.buffered_views, estimator.prepare)
    assert bad.value.code == Result.INVALID_GOAL


def test_a_goal_s_preset_replaces_the_solver_values_only():
    values = {"preset": "", "object_distance": 0.7, **{name: None for name in SOLVER_PARAMETERS}}
    assert goal_values(values, EstimatePoses.Goal()) is values
    fast = goal_values(values, EstimatePoses.Goal(preset="fast"))
    config = SolverConfig.preset("fast")
    assert fast == {**values, "preset": "fast", **{name: getattr(config, name) for name in SOLVER_PARAMETERS}}
    with pytest.raises(EstimateRefused, match="preset") as unknown:
        goal_values(values, EstimatePoses.Goal(preset="fastest"))
    assert unknown.value.code == Result.INVALID_GOAL
