"""An empty ``model_path`` loads the embedded demo model loudly, or says clearly that none is installed."""
from __future__ import annotations

import json
import logging

import pytest
import torch

from idpose_core.demo_model import DemoDiffusionModel, DemoModelConfig, DemoPredictor
from idpose_core.demo_model import predictor as demo_predictor
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
    assert "EMBEDDED DEMO MODEL" in caplog.text and "Zero-1-to-3" in caplog.text


def test_empty_model_path_without_an_embedded_model_is_a_load_error(tmp_path, monkeypatch):
    monkeypatch.setattr(demo_predictor, "EMBEDDED_MODEL_DIR", tmp_path)
    with pytest.raises(ModelLoadError, match="no embedded demo model is installed"):
        load_predictor("  ", device="cpu")
