"""Zero-1-to-3 (Liu et al. 2023) on diffusers and transformers, as an ID-Pose ``NoisePredictor``."""
from idpose_core.zero123.config import Zero123Config
from idpose_core.zero123.errors import ModelLoadError
from idpose_core.zero123.zero123_predictor import Zero123Predictor

__all__ = ["ModelLoadError", "Zero123Config", "Zero123Predictor"]
