"""The estimator's parameters: descriptors, the shipped YAML, and changes rejected with a reason.

Runs rclpy's real parameter machinery on a bare node that declares the estimator's parameters
(the node itself, with a model, is exercised in test_estimator_node.py).
"""
from pathlib import Path

import pytest
import yaml
from rcl_interfaces.msg import ParameterType
from rclpy.exceptions import InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter

from idpose_core.solver import SolverConfig
from idpose_ros.node.parameters import (
    SOLVER_PARAMETERS,
    declare_parameters,
    node_settings,
    parameter_table,
    solver_config,
)

ROOT = Path(__file__).resolve().parents[1]
READ_ONLY = {"model_path", "device", "precision", "load_model_at_startup", "autostart", "publish_tf",
             "diagnostics_period", "gravity", "imu_to_optical", "imu_window", "input_tolerance",
             "record_dir", "resume", "record_max_bytes"}


@pytest.fixture
def node(ros_context):
    node = Node("parameters_under_test", context=ros_context)
    declare_parameters(node)
    yield node
    node.destroy_node()


def test_the_shipped_yaml_lists_every_parameter_with_its_default():
    shipped = yaml.safe_load((ROOT / "config" / "estimator.yaml").read_text())["idpose_estimator"]["ros__parameters"]
    assert shipped == {name: default for name, default, _ in parameter_table()}


@pytest.mark.slow  # starts a node or a process
def test_solver_parameters_default_to_the_solver_defaults_and_build_its_config(node):
    values = {name: node.get_parameter(name).value for name, _, _ in parameter_table()}
    config = solver_config(values)
    defaults = SolverConfig()
    assert all(getattr(config, name) == getattr(defaults, name) for name in SOLVER_PARAMETERS)
    assert config.anchor_polar_deg == node_settings(values).anchor_polar_deg == 90.0
    config.validate()


@pytest.mark.slow  # starts a node or a process
def test_every_parameter_is_described_and_bounded_where_numeric(node):
    for name, _, _ in parameter_table():
        (descriptor,) = node.describe_parameters([name])
        assert len(descriptor.description) > 20, name
        assert descriptor.read_only == (name in READ_ONLY), name
        if descriptor.type == ParameterType.PARAMETER_INTEGER:
            assert descriptor.integer_range, name
        if descriptor.type == ParameterType.PARAMETER_DOUBLE:
            assert descriptor.floating_point_range, name
    (device,) = node.describe_parameters(["device"])
    assert "auto, cpu, cuda" in device.description


@pytest.mark.parametrize("name, value, reason", [
    ("max_views", 1, "out of range"),
    ("max_views", 65, "out of range"),
    ("min_view_interval", -0.5, "out of range"),
    ("anchor_polar_deg", 181.0, "out of range"),
    ("refine_lr", 0.0, "SolverConfig.refine_lr"),
    ("capture_mode", "sometimes", "capture_mode must be one of auto, on_request"),
    ("variant", "best", "variant must be one of full, tr, naive"),
    ("views_per_estimate", 9, "views_per_estimate (9) cannot exceed max_views (8)"),
    ("next_view_polar_deg", [100.0, 30.0], "reachable polar_deg must be an ordered range"),
    ("next_view_distance", [0.5], "next_view_distance must be two numbers"),
    ("next_view_criterion", "nearest", "next_view_criterion must be one of bridge, contrast"),
    ("model_path", "/elsewhere", "read-only"),
    ("device", "cuda", "read-only"),
    ("max_views", "eight", "type"),
])
@pytest.mark.slow  # starts a node or a process
def test_invalid_changes_are_rejected_with_a_reason(node, name, value, reason):
    before = node.get_parameter(name).value
    (result,) = node.set_parameters([Parameter(name, value=value)])
    assert not result.successful
    assert reason.lower() in result.reason.lower(), result.reason
    assert node.get_parameter(name).value == before


@pytest.mark.slow  # starts a node or a process
def test_valid_changes_are_taken_together(node):
    results = node.set_parameters_atomically([Parameter("max_views", value=12),
                                              Parameter("views_per_estimate", value=10),
                                              Parameter("refine_steps_per_view", value=5)])
    assert results.successful, results.reason
    values = [node.get_parameter(name).value for name in ("views_per_estimate", "refine_steps_per_view")]
    assert values == [10, 5]


@pytest.mark.slow  # starts a node or a process
def test_an_invalid_override_at_start_up_names_the_problem(ros_context):
    node = Node("bad_overrides", context=ros_context,
                parameter_overrides=[Parameter("capture_mode", value="continuous")])
    try:
        with pytest.raises(InvalidParameterValueException, match="capture_mode must be one of"):
            declare_parameters(node)
    finally:
        node.destroy_node()


@pytest.mark.slow  # starts a node or a process
def test_setting_a_preset_sets_the_exposed_solver_parameters_and_the_rest_comes_from_it(node):
    assert node.set_parameters([Parameter("preset", value="ifusion")])[0].successful
    ifusion = SolverConfig.preset("ifusion")
    assert all(node.get_parameter(name).value == getattr(ifusion, name) for name in SOLVER_PARAMETERS)
    config = solver_config({name: node.get_parameter(name).value for name, _, _ in parameter_table()})
    assert config.search == "starts" and config.start_steps == ifusion.start_steps
    # a solver parameter set in the same call as the preset wins over the preset's value
    assert node.set_parameters_atomically([Parameter("preset", value="fast"),
                                           Parameter("probe_batch", value=8)]).successful
    assert node.get_parameter("probe_batch").value == 8
    assert node.get_parameter("refine_steps_per_view").value == SolverConfig.preset("fast").refine_steps_per_view
    assert solver_config({name: node.get_parameter(name).value for name, _, _ in parameter_table()}).search == "grid"
    assert not node.set_parameters([Parameter("preset", value="slow")])[0].successful


@pytest.mark.slow  # starts a node or a process
def test_a_preset_given_at_start_up_sets_the_solver_parameters(ros_context):
    node = Node("preset_at_start", context=ros_context, parameter_overrides=[Parameter("preset", value="fast")])
    try:
        declare_parameters(node)
        assert node.get_parameter("keep_top").value == SolverConfig.preset("fast").keep_top
    finally:
        node.destroy_node()
