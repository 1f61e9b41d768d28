"""One entry point from a user's ``model_path`` to a ready ``NoisePredictor``."""
from __future__ import annotations

from pathlib import Path

import torch

from idpose_core.predictor import NoisePredictor
from idpose_core.zero123 import ModelLoadError, Zero123Predictor

PRECISIONS = {"auto": None, "float32": torch.float32, "float16": torch.float16, "bfloat16": torch.bfloat16}
CHECKPOINT_SUFFIXES = (".ckpt", ".pt", ".pth", ".safetensors")


def load_predictor(model_path: str, device: str = "auto", precision: str = "auto") -> NoisePredictor:
    """A diffusers-layout Zero-1-to-3 folder or an original LDM checkpoint file -> predictor.

    ``precision``: "auto" (float32 on CPU, bfloat16/float16 on CUDA), "float32", "float16",
    "bfloat16". Raises ``ModelLoadError`` naming the path, the problem and what to download.
    """
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {sorted(PRECISIONS)}, got {precision!r}")
    if not str(model_path).strip():
        raise ModelLoadError("model_path", "empty: no model given")
    path = Path(model_path).expanduser()
    if path.is_dir():
        return Zero123Predictor.from_pretrained(path, device=device, dtype=PRECISIONS[precision])
    if path.is_file() and path.suffix in CHECKPOINT_SUFFIXES:
        return Zero123Predictor.from_ldm_checkpoint(path, device=device, dtype=PRECISIONS[precision])
    if path.is_file():
        raise ModelLoadError(path, f"unknown model file type (expected a folder or {', '.join(CHECKPOINT_SUFFIXES)})")
    raise ModelLoadError(path, "no such folder or file")
