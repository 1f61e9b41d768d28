"""SolverConfig: paper defaults, presets, range checks naming the field, polar candidates."""
import math

import numpy as np
import pytest

from idpose_core.solver import SolverConfig


def test_defaults_are_the_official_settings():
    config = SolverConfig()
    assert (config.azimuth_candidates, config.probe_batch, config.probe_t) == (8, 16, 0.2)
    assert (config.adjust_steps, config.adjust_lr, config.keep_top) == (10, 10.0, 5)
    assert (config.refine_steps_per_view, config.refine_lr, config.refine_t_range) == (600, 1.0, (0.2, 0.21))
    assert config.average_last == 20 and config.variant == "full"
    assert SolverConfig.preset("default") == config


def test_fast_preset_is_cheaper_and_accepts_overrides():
    fast = SolverConfig.preset("fast", seed=3)
    assert fast.seed == 3
    assert fast.refine_steps_per_view < SolverConfig().refine_steps_per_view
    assert fast.probe_batch < SolverConfig().probe_batch
    with pytest.raises(ValueError, match="unknown solver preset"):
        SolverConfig.preset("turbo")


@pytest.mark.parametrize(
    "field, value",
    [
        ("variant", "pairwise"), ("azimuth_candidates", 0), ("probe_batch", 0), ("probe_t", 1.0),
        ("adjust_steps", -1), ("adjust_lr", 0.0), ("keep_top", 0), ("refine_lr", math.nan),
        ("refine_t_range", (0.3, 0.2)), ("average_last", 0), ("max_batch", 0), ("seed", -1),
        ("polar_candidates_deg", ()), ("polar_candidates_deg", (200.0,)), ("anchor_polar_deg", 180.0),
        ("runner_up_steps", -2), ("ambiguity_margin", -0.1), ("azimuth_refinements", -1),
        ("gravity_fallback", "turbo"), ("gravity_fallback", "live"),
    ],
)
def test_out_of_range_fields_are_named(field, value):
    with pytest.raises(ValueError, match=field):
        SolverConfig(**{field: value}).validate()


def test_polar_candidates_default_given_and_from_the_anchor():
    assert np.allclose(np.degrees(SolverConfig().polar_candidates()), [-120, -60, 0, 60, 120])
    assert np.allclose(np.degrees(SolverConfig(polar_candidates_deg=(10.0,)).polar_candidates()), [10])
    from_anchor = np.degrees(SolverConfig(anchor_polar_deg=60.0).polar_candidates())
    assert 0.0 in from_anchor
    assert np.allclose(np.diff(np.sort(from_anchor)), 45.0)
    absolute = 60.0 + from_anchor
    assert absolute.min() > 0.0 and absolute.max() < 180.0
    assert absolute.min() - 45.0 <= 0.0 and absolute.max() + 45.0 >= 180.0, "must cover the whole range"


def test_recommended_settings_fill_only_settings_the_caller_did_not_choose():
    recommended = {"probe_t": 0.85, "refine_t_range": (0.8, 0.9), "refine_lr": 0.5}
    config = SolverConfig.preset("fast", refine_lr=2.0).with_recommended(recommended)
    assert config.probe_t == 0.85 and config.refine_t_range == (0.8, 0.9)
    assert config.refine_lr == 2.0  # the caller's own choice wins
    assert config.refine_steps_per_view == SolverConfig.preset("fast").refine_steps_per_view
    assert SolverConfig().with_recommended({}) == SolverConfig()


def test_a_chosen_value_equal_to_the_paper_default_still_wins():
    recommended = {"probe_t": 0.4, "refine_t_range": (0.4, 0.41)}
    assert SolverConfig(probe_t=0.2).with_recommended(recommended).probe_t == 0.2
    assert SolverConfig.preset("default", probe_t=0.2).with_recommended(recommended).probe_t == 0.2
    updated = SolverConfig().updated(refine_t_range=(0.2, 0.21))
    assert updated.with_recommended(recommended).refine_t_range == (0.2, 0.21)
    assert SolverConfig().with_recommended(recommended).probe_t == 0.4  # left alone: the model's value


def test_chosen_settings_are_tracked_through_updates_and_unknown_names_refused():
    config = SolverConfig(seed=3).updated(probe_batch=2)
    assert config.chosen == {"seed", "probe_batch"} and (config.seed, config.probe_batch) == (3, 2)
    assert config.updated(seed=4).seed == 4  # a chosen setting can be changed again
    assert SolverConfig.preset("fast").chosen == {"probe_batch", "adjust_top", "keep_top", "refine_steps_per_view",
                                                  "runner_up_steps", "runner_up_gate"}
    assert SolverConfig.preset("ifusion", variant="tr").chosen >= {"search", "variant"}
    with pytest.raises(TypeError, match="no settings \\['probe_time'\\]"):
        SolverConfig(probe_time=0.5)


def test_recommended_settings_are_checked():
    with pytest.raises(ValueError, match="unknown SolverConfig fields \\['probe_time'\\]"):
        SolverConfig().with_recommended({"probe_time": 0.5})
    with pytest.raises(ValueError, match="probe_t"):
        SolverConfig().with_recommended({"probe_t": 1.5})


def test_live_falls_back_to_fast_keeping_what_does_not_shape_the_schedule():
    live = SolverConfig.preset("live", seed=4, refine_lr=0.5, probe_batch=3).updated(anchor_polar_deg=70.0)
    fallback = live.fallback()
    fast = SolverConfig.preset("fast")
    assert (fallback.seed, fallback.refine_lr, fallback.anchor_polar_deg) == (4, 0.5, 70.0)
    for name in ("probe_batch", "azimuth_candidates", "adjust_steps", "refine_steps_per_view", "azimuth_refinements",
                 "runner_up_steps"):
        assert getattr(fallback, name) == getattr(fast, name), name
    assert fallback.gravity_fallback is None
    with pytest.raises(ValueError, match="no gravity_fallback"):
        fast.fallback()
