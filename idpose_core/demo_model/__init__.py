"""A small Zero-1-to-3-style view-conditioned diffusion model, trained here on the demo objects."""
from idpose_core.demo_model.config import DemoModelConfig
from idpose_core.demo_model.demo_predictor import EMBEDDED_MODEL_DIR, DemoPredictor
from idpose_core.demo_model.model import DemoDiffusionModel

__all__ = ["DemoDiffusionModel", "DemoModelConfig", "DemoPredictor", "EMBEDDED_MODEL_DIR"]
