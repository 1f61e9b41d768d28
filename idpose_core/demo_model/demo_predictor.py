"""``DemoPredictor``: the small demo model behind the ``NoisePredictor`` protocol, frozen for inversion."""
from __future__ import annotations

import json
from pathlib import Path

import torch

from idpose_core.demo_model.model import DemoDiffusionModel
from idpose_core.noise_predictor import Views
from idpose_core.zero123.zero123_predictor import reduced_precision

EMBEDDED_MODEL_DIR = Path(__file__).resolve().parents[1] / "assets" / "demo_model"
SOLVER_DEFAULTS_FILE = "solver_defaults.json"


class DemoPredictor:
    """Noise predictor of the demo model; weights frozen, gradients flow to the pose only.

    ``encode`` downsamples preprocessed views (N, 3, H, W) in [-1, 1] to the model resolution: the
    clean targets become ``Views.latents`` (pixel space, no VAE) and the references' CLIP embeddings
    and images go into ``Views.conditioning``. Weights stay float32; with another ``dtype`` only the UNet
    runs under autocast (bfloat16 on CPUs with native support): the encoder (once per view) and the
    pose path stay float32, and so do the errors.
    """

    def __init__(self, model: DemoDiffusionModel, solver_defaults: dict | None = None,
                 dtype: torch.dtype = torch.float32):
        """``solver_defaults``: ``SolverConfig`` overrides recommended for this model (its probe timesteps)."""
        self.model = model.eval().requires_grad_(False)
        self.num_train_timesteps = int(model.config.num_train_timesteps)
        self.solver_defaults = dict(solver_defaults or {})
        self.dtype = dtype

    @classmethod
    def from_pretrained(cls, folder: Path | str, device: str | torch.device = "cpu",
                        dtype: torch.dtype = torch.float32) -> DemoPredictor:
        """Load a model folder (``config.json``, ``model.safetensors``, optional ``solver_defaults.json``)."""
        folder = Path(folder)
        defaults_path = folder / SOLVER_DEFAULTS_FILE
        defaults = json.loads(defaults_path.read_text()) if defaults_path.is_file() else {}
        defaults = {key: tuple(value) if isinstance(value, list) else value for key, value in defaults.items()}
        return cls(DemoDiffusionModel.from_pretrained(folder).to(device), defaults, dtype)

    @classmethod
    def embedded(cls, device: str | torch.device = "cpu", dtype: torch.dtype = torch.float32) -> DemoPredictor:
        """The demo model shipped inside the package (``idpose_core/assets/demo_model``)."""
        return cls.from_pretrained(EMBEDDED_MODEL_DIR, device, dtype)

    @property
    def device(self) -> torch.device:
        return next(self.model.parameters()).device

    @torch.no_grad()
    def encode(self, images: torch.Tensor) -> Views:
        """Images (N, 3, H, W) in [-1, 1] -> Views: latents (N, 3, r, r), conditioning {"image", "embedding" (N, D)}."""
        if images.ndim != 4 or images.shape[1] != 3:
            raise ValueError(f"images must be (N, 3, H, W) in [-1, 1], got shape {tuple(images.shape)}")
        small = self.model.downsample(images.to(self.device, torch.float32))
        return Views(latents=small, conditioning={"image": small, "embedding": self.model.embed(small)})

    def noise_error(self, views: Views, ref: torch.Tensor, tgt: torch.Tensor, pose: torch.Tensor,
                    t: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
        """Per-sample noise MSE (B,) of denoising view ``tgt[b]`` from view ``ref[b]`` under ``pose[b]`` at ``t[b]``."""
        device = self.device
        ref, tgt, t = ref.to(device), tgt.to(device), t.to(device)
        noise = noise.to(device, torch.float32)
        noisy = self.model.add_noise(views.latents[tgt], noise, t)
        with reduced_precision(self.device, self.dtype):
            predicted = self.model.predict_noise(noisy, views.conditioning["image"][ref],
                                                 views.conditioning["embedding"][ref],
                                                 pose.to(device, torch.float32), t)
        return (predicted.float() - noise).pow(2).flatten(1).mean(1)
