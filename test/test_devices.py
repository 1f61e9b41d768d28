"""A device that is not there is one clear error naming it and what is available: in load_predictor, the
CLIs and the node (here, where torch has no CUDA or no GPU is visible, "cuda" is such a device)."""
import pytest
import torch
from rclpy.parameter import Parameter
from test_evaluate_bag_cli import DEMO_BAG

from idpose_core.devices import DeviceUnavailable, available_devices, resolve_device
from idpose_core.model_loading import load_predictor
from idpose_ros.evaluate_bag import main as evaluate_bag
from idpose_ros.node.estimator_node import EstimatorNode

needs_no_cuda = pytest.mark.skipif(torch.cuda.is_available(), reason="a CUDA device is visible here")


def test_known_devices_resolve():
    assert resolve_device("cpu") == torch.device("cpu")
    assert resolve_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")
    assert available_devices()[0] == "cpu"


@pytest.mark.parametrize("name, reason", [("gpu", "not a torch device"), ("mps", "only cpu and cuda are supported"),
                                          ("cuda:64", "not available")])
def test_unknown_or_absent_devices_are_refused_with_what_is_available(name, reason):
    with pytest.raises(DeviceUnavailable, match=reason) as raised:
        resolve_device(name)
    assert f"'{name}'" in str(raised.value) and "available: cpu" in str(raised.value)


@needs_no_cuda
def test_load_predictor_refuses_cuda_before_reading_anything(tmp_path):
    with pytest.raises(DeviceUnavailable, match="device 'cuda' is not available: .*available: cpu"):
        load_predictor(str(tmp_path / "no_such_model"), device="cuda")


@needs_no_cuda
def test_evaluate_bag_on_an_absent_device_is_one_line_not_a_traceback(capsys):
    assert evaluate_bag([str(DEMO_BAG), "--device", "cuda", "--out", "unused"]) == 2
    err = capsys.readouterr().err
    assert "device 'cuda' is not available" in err and "Traceback" not in err


@pytest.mark.slow
@needs_no_cuda
def test_the_node_names_the_device_and_stays_up(ros_context):
    node = EstimatorNode(context=ros_context, namespace="/absent_device",
                         parameter_overrides=[Parameter("device", value="cuda"), Parameter("publish_tf", value=False)])
    try:
        assert node.lifecycle_state == "unconfigured"
        assert "DeviceUnavailable: device 'cuda' is not available" in node.status().last_error
        assert "model_path" not in node.status().last_error
    finally:
        node.destroy_node()
