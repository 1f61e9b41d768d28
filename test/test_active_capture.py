"""The closed capture loop the next-view benchmark runs: starts, rendered views with exact gravity, each policy's
camera inside the reachable set, one step per estimate with errors against the rendered truth.

The model is the tiny random one: the loop's bookkeeping is checked, not its accuracy.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from idpose_core.cameras import first_camera_frame_poses
from idpose_core.evaluation.active_capture import (
    MIN_START_SEPARATION_DEG,
    POLICIES,
    largest_gap_camera,
    random_starts,
    rendered_view,
    run_loop,
)
from idpose_core.gravity import polar_angle
from idpose_core.next_view import ReachableSet
from idpose_core.pipeline import PipelineSettings
from idpose_core.solver import SolverConfig
from idpose_core.synthetic.scenes import TRAINING_LIGHT, SceneRenderer, demo_objects
from idpose_core.zero123 import Zero123Predictor

REACHABLE = ReachableSet(polar_deg=(50.0, 90.0), azimuth_deg=(-120.0, 120.0), step_deg=30.0)
SETTINGS = PipelineSettings(SolverConfig(azimuth_candidates=2, probe_batch=1, adjust_steps=0, keep_top=1,
                                         refine_steps_per_view=2, average_last=1, runner_up_steps=1),
                            object_distance=2.0, image_size=32, reachable=REACHABLE)


@pytest.fixture(scope="module")
def predictor():
    return Zero123Predictor.tiny(seed=0)


def degrees_between(a: np.ndarray, b: np.ndarray) -> float:
    relative = first_camera_frame_poses(np.stack([a, b]))[1]
    return math.degrees(math.acos(np.clip(relative[2, 2], -1.0, 1.0)))


def test_starts_are_reachable_and_apart():
    starts = random_starts(demo_objects()[:2], [TRAINING_LIGHT], 12, REACHABLE, 2.0, np.random.default_rng(0))
    assert [s.spec.name for s in starts[:3]] == [demo_objects()[0].name, demo_objects()[1].name,
                                                demo_objects()[0].name]
    for start in starts:
        assert 50.0 <= math.degrees(start.anchor[0]) <= 90.0 and 50.0 <= math.degrees(start.second[0]) <= 90.0
        assert degrees_between(start.anchor, start.second) >= MIN_START_SEPARATION_DEG
        assert start.anchor[2] == start.second[2] == 2.0


def test_a_rendered_view_carries_its_true_gravity():
    with SceneRenderer(demo_objects()[0], image_size=32) as renderer:
        view = rendered_view(renderer, np.array([math.radians(70.0), 1.0, 2.0]), TRAINING_LIGHT)
    assert math.degrees(polar_angle(view.gravity_up)) == pytest.approx(70.0)
    assert view.alpha.dtype == np.uint8 and view.alpha.max() == 255


@pytest.mark.parametrize("policy", POLICIES)
def test_each_policy_adds_reachable_views_and_every_step_is_scored(predictor, policy):
    (start,) = random_starts(demo_objects()[:1], [TRAINING_LIGHT], 1, REACHABLE, 2.0, np.random.default_rng(1))
    steps = run_loop(predictor, start, policy, SETTINGS, 4, 32, np.random.default_rng(2))
    assert [step.views for step in steps] == [2, 3, 4]
    for step in steps:
        assert step.rotation_errors_deg.shape == step.ambiguous.shape == (step.views - 1,)
        assert np.all((step.rotation_errors_deg >= 0.0) & (step.rotation_errors_deg <= 180.0))
        assert step.forward_samples > 0
    assert steps[-1].next_camera is None
    for step in steps[:-1]:
        polar, azimuth = np.degrees(step.next_camera[:2])
        relative = (azimuth - math.degrees(start.anchor[1]) + 180.0) % 360.0 - 180.0
        assert 50.0 - 1e-6 <= polar <= 90.0 + 1e-6 and -120.0 - 1e-6 <= relative <= 120.0 + 1e-6


def test_an_unknown_policy_is_named(predictor):
    (start,) = random_starts(demo_objects()[:1], [TRAINING_LIGHT], 1, REACHABLE, 2.0, np.random.default_rng(1))
    with pytest.raises(ValueError, match="unknown capture policy 'closest'"):
        run_loop(predictor, start, "closest", SETTINGS, 3, 32, np.random.default_rng(2))


def test_the_largest_gap_is_split_at_the_anchor_s_polar_angle():
    spheres = np.array([[math.radians(60.0), 0.0, 2.0], [math.radians(80.0), math.radians(100.0), 2.0]])
    camera = largest_gap_camera(spheres, ReachableSet())
    assert np.degrees(camera[:2]) == pytest.approx([60.0, -130.0])
