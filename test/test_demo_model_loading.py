"""An empty ``model_path`` loads the embedded demo model loudly, or says clearly that none is installed."""
from __future__ import annotations

import json
import logging

import pytest
import torch

from idpose_core.demo_model import DemoDiffusionModel, DemoModelConfig, DemoPredictor, demo_predictor
from idpose_core.model_loading import load_predictor
from idpose_core.zero123 import ModelLoadError

TINY = DemoModelConfig(resolution=16, block_out_channels=(8, 16), norm_num_groups=4, embedding_dim=16,
                       encoder_layers=1, encoder_heads=2)


def test_empty_model_path_loads_the_embedded_model_with_a_warning(tmp_path, monkeypatch, caplog):
    torch.manual_seed(0)
    DemoDiffusionModel(TINY).save_pretrained(tmp_path)
    (tmp_path / "solver_defaults.json").write_text(json.dumps({"probe_t": 0.4, "refine_t_range": [0.4, 0.41]}))
    monkeypatch.setattr(demo_predictor, "EMBEDDED_MODEL_DIR", tmp_path)
    with caplog.at_level(logging.WARNING):
        predictor = load_predictor("", device="cpu")
    assert isinstance(predictor, DemoPredictor)
    assert predictor.model.config == TINY
    assert predictor.solver_defaults == {"probe_t": 0.4, "refine_t_range": (0.4, 0.41)}
    assert "EMBEDDED DEMO MODEL" in caplog.text and "at chance" in caplog.text and "Zero-1-to-3" in caplog.text


def test_a_demo_model_folder_as_model_path_loads_that_model(tmp_path, caplog):
    torch.manual_seed(1)
    DemoDiffusionModel(TINY).save_pretrained(tmp_path / "trained")
    with caplog.at_level(logging.WARNING):
        predictor = load_predictor(str(tmp_path / "trained"), device="cpu")
    assert isinstance(predictor, DemoPredictor) and predictor.model.config == TINY
    assert "trained on synthetic objects only" in caplog.text
    (tmp_path / "trained" / "config.json").unlink()  # no longer a demo model folder: read as Zero-1-to-3's
    with pytest.raises(ModelLoadError, match="not a Zero-1-to-3 diffusers folder"):
        load_predictor(str(tmp_path / "trained"), device="cpu")


def test_empty_model_path_without_an_embedded_model_is_a_load_error(tmp_path, monkeypatch):
    monkeypatch.setattr(demo_predictor, "EMBEDDED_MODEL_DIR", tmp_path)
    with pytest.raises(ModelLoadError, match="no embedded demo model is installed"):
        load_predictor("  ", device="cpu")


def test_the_precision_reaches_the_demo_model_and_bfloat16_stays_close(tmp_path, monkeypatch):
    torch.manual_seed(0)
    DemoDiffusionModel(TINY).save_pretrained(tmp_path)
    monkeypatch.setattr(demo_predictor, "EMBEDDED_MODEL_DIR", tmp_path)
    full, half = load_predictor("", device="cpu", precision="float32"), load_predictor("", device="cpu",
                                                                                       precision="bfloat16")
    assert (full.dtype, half.dtype) == (torch.float32, torch.bfloat16)
    images = torch.rand(2, 3, 32, 32, generator=torch.Generator().manual_seed(1)) * 2 - 1
    index, t = torch.tensor([0, 1]), torch.tensor([300, 600])
    noise = torch.randn(2, 3, 16, 16, generator=torch.Generator().manual_seed(2))
    errors, gradients = [], []
    for predictor in (full, half):
        pose = torch.tensor([[0.3, 1.0, 0.0], [-0.2, 4.0, 0.0]], requires_grad=True)
        error = predictor.noise_error(predictor.encode(images), index, 1 - index, pose, t, noise)
        error.sum().backward()
        errors.append(error.detach())
        gradients.append(pose.grad[:, :2])
    assert errors[0].dtype == errors[1].dtype == torch.float32
    assert not torch.equal(errors[0], errors[1]), "bfloat16 did not change the arithmetic"
    assert torch.allclose(errors[0], errors[1], rtol=0.05)
    assert torch.nn.functional.cosine_similarity(gradients[0].flatten(), gradients[1].flatten(), dim=0) > 0.9


def test_float16_on_the_cpu_is_loaded_with_a_warning(tmp_path, monkeypatch, caplog):
    DemoDiffusionModel(TINY).save_pretrained(tmp_path)
    monkeypatch.setattr(demo_predictor, "EMBEDDED_MODEL_DIR", tmp_path)
    with caplog.at_level(logging.WARNING):
        load_predictor("", device="cpu", precision="float16")
    assert "float16 on the CPU" in caplog.text and "bfloat16" in caplog.text
