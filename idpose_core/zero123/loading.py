"""Zero-1-to-3 in the diffusers folder layout: load (offline, safetensors first) and save.

The layout is the one of the community conversions (``kxic/zero123-xl``, ``bennyguo/zero123-xl-diffusers``):
``unet/`` ``vae/`` ``image_encoder/`` ``cc_projection/`` (or ``clip_camera_projection/``)
``feature_extractor/`` ``scheduler/`` and ``model_index.json``. Weight files load through the
libraries' own loaders, which read safetensors or ``torch.load(weights_only=True)``.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch
from diffusers import AutoencoderKL, DDIMScheduler, UNet2DConditionModel
from safetensors.torch import save_file
from transformers import CLIPVisionModelWithProjection

from idpose_core.zero123.config import CLIP_MEAN, CLIP_STD, SCHEDULER
from idpose_core.zero123.errors import ModelLoadError, summary
from idpose_core.zero123.modules import Zero123Modules, require_fit
from idpose_core.zero123.weight_files import read_weights, weight_file_kind

# Projection folder name -> name of its Linear inside the saved module (both conversions exist).
PROJECTION_FOLDERS = {"cc_projection": "projection", "clip_camera_projection": "proj"}
WEIGHT_FILES = ("diffusion_pytorch_model.safetensors", "diffusion_pytorch_model.bin")
WEIGHT_SUFFIXES = (".safetensors", ".bin")  # checked before the libraries read a part


def load_diffusers_folder(path: str | Path) -> Zero123Modules:
    """Read every part of a diffusers-layout Zero-1-to-3 folder; any problem -> ``ModelLoadError``."""
    root = Path(path).expanduser()
    if not root.is_dir():
        raise ModelLoadError(root, "no such folder")
    projection_folder = next((name for name in PROJECTION_FOLDERS if (root / name).is_dir()), None)
    missing = [name for name in ("unet", "vae", "image_encoder") if not (root / name / "config.json").is_file()]
    if projection_folder is None:
        missing.append("cc_projection")
    if missing:
        raise ModelLoadError(root, f"not a Zero-1-to-3 diffusers folder: missing part(s) {', '.join(missing)}")
    size, mean, std = _clip_preprocessing(root / "feature_extractor")
    modules = Zero123Modules(
        unet=_load_part(root, "unet", UNet2DConditionModel),
        vae=_load_part(root, "vae", AutoencoderKL),
        image_encoder=_load_part(root, "image_encoder", CLIPVisionModelWithProjection),
        cc_projection=_load_projection(root / projection_folder, PROJECTION_FOLDERS[projection_folder]),
        scheduler=_load_scheduler(root / "scheduler"),
        clip_size=size,
        clip_mean=mean,
        clip_std=std,
    )
    return require_fit(modules, root)


def save_diffusers_folder(modules: Zero123Modules, path: str | Path) -> None:
    """Write the community layout with safetensors weights, loadable by ``load_diffusers_folder``."""
    root = Path(path)
    root.mkdir(parents=True, exist_ok=True)
    modules.unet.save_pretrained(root / "unet", safe_serialization=True)
    modules.vae.save_pretrained(root / "vae", safe_serialization=True)
    modules.image_encoder.save_pretrained(root / "image_encoder", safe_serialization=True)
    modules.scheduler.save_pretrained(root / "scheduler")
    linear = modules.cc_projection
    (root / "cc_projection").mkdir(exist_ok=True)
    _write_json(
        root / "cc_projection" / "config.json",
        {"_class_name": "CCProjection", "in_channel": linear.in_features, "out_channel": linear.out_features},
    )
    save_file(
        {f"projection.{name}": tensor.detach().contiguous().cpu() for name, tensor in linear.state_dict().items()},
        str(root / "cc_projection" / WEIGHT_FILES[0]),
    )
    (root / "feature_extractor").mkdir(exist_ok=True)
    _write_json(root / "feature_extractor" / "preprocessor_config.json", _preprocessor_config(modules))
    _write_json(root / "model_index.json", _model_index())


def _load_part(root: Path, name: str, cls: Any) -> Any:
    """``cls.from_pretrained`` on ``root/name``, refusing damaged, missing, unexpected or mis-shaped weights."""
    for file in sorted((root / name).glob("*")):
        if file.suffix in WEIGHT_SUFFIXES and file.is_file():
            try:
                weight_file_kind(file)
            except (ValueError, OSError) as error:
                raise ModelLoadError(root, f"part '{name}': {file.name} is {error}") from error
    try:
        extra = {"low_cpu_mem_usage": False} if cls is not CLIPVisionModelWithProjection else {}
        model, info = cls.from_pretrained(root / name, local_files_only=True, output_loading_info=True, **extra)
    except Exception as error:  # noqa: BLE001 - whatever the library says, one error naming the part
        raise ModelLoadError(root, f"cannot load part '{name}': {summary(error)}") from error
    for kind in ("missing_keys", "mismatched_keys", "unexpected_keys"):
        keys = sorted(map(str, info.get(kind) or ()))
        if keys:
            raise ModelLoadError(root, f"part '{name}' has {kind.replace('_', ' ')}: {', '.join(keys[:5])}")
    return model


def _load_projection(folder: Path, linear_name: str) -> torch.nn.Linear:
    """The 772 -> 768 Linear from ``config.json`` + safetensors (or a weights-only ``.bin``)."""
    config = _read_json(folder / "config.json", folder.parent)
    in_features = config.get("in_channel", config.get("embedding_dim", 0) + config.get("additional_embeddings", 0))
    out_features = config.get("out_channel", config.get("embedding_dim"))
    weights = _read_weights(folder, folder.parent)
    state = {key.removeprefix(f"{linear_name}."): value for key, value in weights.items()}
    linear = torch.nn.Linear(int(in_features), int(out_features))
    try:
        linear.load_state_dict(state)
    except RuntimeError as error:
        raise ModelLoadError(folder.parent,
                             f"part '{folder.name}' does not match its config: {summary(error)}") from error
    return linear


def _read_weights(folder: Path, root: Path) -> dict[str, torch.Tensor]:
    """Safetensors first, else a pickle loaded with ``weights_only=True``."""
    for file_name in WEIGHT_FILES:
        if (folder / file_name).is_file():
            weights = read_weights(folder / file_name)
            if not isinstance(weights, dict):
                raise ModelLoadError(root, f"{folder.name}/{file_name} is not a state_dict of tensors")
            return weights
    raise ModelLoadError(root, f"part '{folder.name}' has no weights ({' or '.join(WEIGHT_FILES)})")


def _load_scheduler(folder: Path) -> DDIMScheduler:
    """The folder's schedule when present, else Zero-1-to-3's own (scaled_linear 0.00085..0.012)."""
    if (folder / "scheduler_config.json").is_file():
        return DDIMScheduler.from_pretrained(folder)
    return DDIMScheduler(**SCHEDULER)


def _clip_preprocessing(folder: Path) -> tuple[int, tuple[float, ...], tuple[float, ...]]:
    """CLIP input size and pixel statistics from ``preprocessor_config.json``, else ViT-L/14's."""
    config = _read_json(folder / "preprocessor_config.json", folder.parent) if folder.is_dir() else {}
    crop = config.get("crop_size", 224)
    size = crop["height"] if isinstance(crop, dict) else crop
    return int(size), tuple(config.get("image_mean", CLIP_MEAN)), tuple(config.get("image_std", CLIP_STD))


def _preprocessor_config(modules: Zero123Modules) -> dict[str, Any]:
    """A ``CLIPImageProcessor`` config describing exactly the preprocessing ``encode`` applies."""
    size = modules.clip_size
    return {
        "image_processor_type": "CLIPImageProcessor",
        "do_resize": True,
        "size": {"shortest_edge": size},
        "resample": 3,
        "do_center_crop": True,
        "crop_size": {"height": size, "width": size},
        "do_rescale": True,
        "rescale_factor": 1 / 255,
        "do_normalize": True,
        "image_mean": list(modules.clip_mean),
        "image_std": list(modules.clip_std),
        "do_convert_rgb": True,
    }


def _model_index() -> dict[str, Any]:
    """The pipeline index of the diffusers community Zero-1-to-3 pipeline, for tool compatibility."""
    return {
        "_class_name": "Zero1to3StableDiffusionPipeline",
        "cc_projection": ["pipeline_zero1to3", "CCProjection"],
        "feature_extractor": ["transformers", "CLIPImageProcessor"],
        "image_encoder": ["transformers", "CLIPVisionModelWithProjection"],
        "requires_safety_checker": False,
        "safety_checker": [None, None],
        "scheduler": ["diffusers", "DDIMScheduler"],
        "unet": ["diffusers", "UNet2DConditionModel"],
        "vae": ["diffusers", "AutoencoderKL"],
    }


def _read_json(file: Path, root: Path) -> dict[str, Any]:
    try:
        return json.loads(file.read_text())
    except (OSError, ValueError) as error:
        raise ModelLoadError(root, f"cannot read {file.relative_to(root)}: {summary(error)}") from error


def _write_json(file: Path, content: dict[str, Any]) -> None:
    file.write_text(json.dumps(content, indent=2) + "\n")
