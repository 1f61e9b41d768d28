"""One entry point from a user's ``model_path`` to a ready ``NoisePredictor``."""
from __future__ import annotations

import logging
from pathlib import Path

import torch

from idpose_core.demo_model import DemoPredictor, demo_predictor
from idpose_core.demo_model.model import WEIGHTS_FILE
from idpose_core.devices import resolve_device
from idpose_core.noise_predictor import NoisePredictor
from idpose_core.zero123 import ModelLoadError, Zero123Predictor
from idpose_core.zero123.zero123_predictor import resolve_dtype

PRECISIONS = {"auto": None, "float32": torch.float32, "float16": torch.float16, "bfloat16": torch.bfloat16}
CHECKPOINT_SUFFIXES = (".ckpt", ".pt", ".pth", ".safetensors")


def load_predictor(model_path: str, device: str = "auto", precision: str = "auto") -> NoisePredictor:
    """A diffusers-layout Zero-1-to-3 folder or an original LDM checkpoint file -> predictor.

    An empty ``model_path`` loads the embedded demo model (``idpose_core/assets/demo_model``) with a
    loud warning: it only knows the demo objects; real objects need Zero-1-to-3. Where the
    package carries no demo weights, an empty path is a ``ModelLoadError``. A folder holding
    ``model.safetensors`` and ``config.json`` at its top (what ``scripts/train_demo_model.py`` writes) is
    a demo model too.

    ``precision``: "auto" (float32 on CPU, bfloat16/float16 on CUDA), "float32", "float16",
    "bfloat16" (on CPUs with native bfloat16, e.g. avx512_bf16 or AMX, about twice as fast as float32:
    ``bench/README.md``). Raises ``ModelLoadError`` naming the path, the problem and what to download, and
    ``DeviceUnavailable`` (before anything is read) for a device that does not exist here.
    """
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {sorted(PRECISIONS)}, got {precision!r}")
    device = resolve_device(device)
    if precision == "float16" and device.type == "cpu":
        logging.getLogger(__name__).warning(
            "precision float16 on the CPU: PyTorch has no fast float16 CPU kernels, an estimate will be far slower "
            "than in float32; use bfloat16 (CPUs with avx512_bf16 or AMX) or float32")
    dtype = resolve_dtype(PRECISIONS[precision], device)
    if not str(model_path).strip():
        folder = demo_predictor.EMBEDDED_MODEL_DIR
        if not (folder / WEIGHTS_FILE).is_file():
            raise ModelLoadError("model_path", f"empty, and no embedded demo model is installed ({folder} has no "
                                 f"{WEIGHTS_FILE}; scripts/train_demo_model.py trains one)")
        logging.getLogger(__name__).warning(
            "model_path is empty: using the EMBEDDED DEMO MODEL (%s), a small diffusion model trained only on "
            "the six synthetic demo objects: on any other object its poses are at chance. Poses of real objects "
            "need Zero-1-to-3 weights (set model_path; docs/weights.md).", folder)
        return DemoPredictor.from_pretrained(folder, device, dtype)
    path = Path(model_path).expanduser()
    if (path / WEIGHTS_FILE).is_file() and (path / "config.json").is_file():
        logging.getLogger(__name__).warning("model_path %s is a small model of scripts/train_demo_model.py, "
                                            "trained on synthetic objects only (docs/demo_model.md)", path)
        return DemoPredictor.from_pretrained(path, device, dtype)
    if path.is_dir():
        return Zero123Predictor.from_pretrained(path, device=device, dtype=PRECISIONS[precision])
    if path.is_file() and path.suffix in CHECKPOINT_SUFFIXES:
        return Zero123Predictor.from_ldm_checkpoint(path, device=device, dtype=PRECISIONS[precision])
    if path.is_file():
        raise ModelLoadError(path, f"unknown model file type (expected a folder or {', '.join(CHECKPOINT_SUFFIXES)})")
    raise ModelLoadError(path, "no such folder or file")
