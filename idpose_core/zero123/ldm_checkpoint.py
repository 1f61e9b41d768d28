"""The original single-file Zero-1-to-3 release (``105000.ckpt``, ``zero123-xl.ckpt``) -> the diffusers parts.

Its ``state_dict`` uses the latent-diffusion names: ``model.diffusion_model.*`` (UNet),
``first_stage_model.*`` (VAE), ``cond_stage_model.model.visual.*`` (OpenAI CLIP ViT-L/14) and
``cc_projection.*``. UNet and VAE are renamed by diffusers' single-file helpers; the CLIP vision
tower is renamed here (OpenAI -> transformers names). The architecture comes from the tensor shapes
(``ldm_architecture``) unless a ``Zero123Config`` is given. Files are read with ``weights_only=True``.
"""
from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from pathlib import Path

import torch
from diffusers import AutoencoderKL, DDIMScheduler, UNet2DConditionModel
from diffusers.loaders.single_file_utils import convert_ldm_unet_checkpoint, convert_ldm_vae_checkpoint
from transformers import CLIPVisionConfig, CLIPVisionModelWithProjection

from idpose_core.zero123.config import Zero123Config
from idpose_core.zero123.errors import ModelLoadError
from idpose_core.zero123.ldm_architecture import CLIP_PREFIX, UNET_PREFIX, VAE_PREFIX, config_from_ldm_state
from idpose_core.zero123.modules import Zero123Modules, require_fit
from idpose_core.zero123.weight_files import read_weights

PROJECTION_PREFIX = "cc_projection."

_RESBLOCK = re.compile(r"^transformer\.resblocks\.(\d+)\.(.+)$")
_RESBLOCK_PARTS = {
    "ln_1.": "layer_norm1.",
    "ln_2.": "layer_norm2.",
    "mlp.c_fc.": "mlp.fc1.",
    "mlp.c_proj.": "mlp.fc2.",
    "attn.out_proj.": "self_attn.out_proj.",
}
_VISUAL_RENAMES = {
    "class_embedding": "vision_model.embeddings.class_embedding",
    "conv1.weight": "vision_model.embeddings.patch_embedding.weight",
    "positional_embedding": "vision_model.embeddings.position_embedding.weight",
}


def load_ldm_checkpoint(path: str | Path, config: Zero123Config | None = None, use_ema: bool = False) -> Zero123Modules:
    """Read a Zero-1-to-3 LDM checkpoint into the parts of ``config`` (default: read from its tensor shapes).

    ``use_ema`` takes the UNet's ``model_ema.*`` copy when the file has one (diffusers' converter).
    """
    file = Path(path).expanduser()
    state = read_state_dict(file)
    missing = [prefix.rstrip(".") for prefix in (UNET_PREFIX, VAE_PREFIX, CLIP_PREFIX, PROJECTION_PREFIX)
               if not any(key.startswith(prefix) for key in state)]
    if missing:
        raise ModelLoadError(file, f"not a Zero-1-to-3 checkpoint: no {', '.join(missing)} weights")
    if config is None:
        try:
            config = config_from_ldm_state(state)
        except ValueError as error:
            raise ModelLoadError(file, f"cannot read the Zero-1-to-3 architecture from its tensors: {error}") from error
    parts = {
        "unet": convert_ldm_unet_checkpoint(state, dict(config.unet), extract_ema=use_ema),
        "vae": convert_ldm_vae_checkpoint(state, dict(config.vae)),
        "cc_projection": {key[len(PROJECTION_PREFIX):]: value for key, value in state.items()
                          if key.startswith(PROJECTION_PREFIX)},
        "image_encoder": clip_visual_to_transformers(state, CLIP_PREFIX),
    }
    loaded = {}
    for name, empty_part in _empty_parts(config).items():
        module = empty_part()
        try:
            module.load_state_dict(parts[name], strict=True, assign=True)
        except RuntimeError as error:
            lines = " ".join(str(error).split())
            raise ModelLoadError(file, f"{name} weights do not match the Zero-1-to-3 shapes: {lines[:400]}") from error
        loaded[name] = module
    modules = Zero123Modules(**loaded, scheduler=DDIMScheduler(**config.scheduler),
                             clip_size=int(config.image_encoder["image_size"]))
    return require_fit(modules, file)


def read_state_dict(file: Path) -> dict[str, torch.Tensor]:
    """The tensors of a PyTorch checkpoint (zip memory-mapped, or legacy pickle) or a safetensors file."""
    if not file.is_file():
        raise ModelLoadError(file, "no such checkpoint file")
    loaded = read_weights(file)
    state = loaded.get("state_dict", loaded) if isinstance(loaded, dict) else loaded
    if not isinstance(state, dict) or not all(isinstance(value, torch.Tensor) for value in state.values()):
        raise ModelLoadError(file, "the checkpoint is not a state_dict of tensors")
    return state


def clip_visual_to_transformers(state: Mapping[str, torch.Tensor], prefix: str) -> dict[str, torch.Tensor]:
    """OpenAI CLIP ``visual.*`` names -> ``CLIPVisionModelWithProjection`` names.

    Fused ``attn.in_proj_*`` splits into q/k/v; ``proj`` (D, P) becomes ``visual_projection.weight``
    (P, D). Unknown keys keep their name so a strict ``load_state_dict`` reports them.
    """
    converted: dict[str, torch.Tensor] = {}
    for key, value in state.items():
        if not key.startswith(prefix):
            continue
        name = key[len(prefix):]
        layer = _RESBLOCK.match(name)
        if name in _VISUAL_RENAMES:
            converted[_VISUAL_RENAMES[name]] = value
        elif name == "proj":
            converted["visual_projection.weight"] = value.t().contiguous()
        elif name.startswith(("ln_pre.", "ln_post.")):
            target = "pre_layrnorm." if name.startswith("ln_pre.") else "post_layernorm."
            converted["vision_model." + target + name.split(".", 1)[1]] = value
        elif layer:
            converted.update(_resblock(f"vision_model.encoder.layers.{layer.group(1)}.", layer.group(2), value))
        else:
            converted[name] = value
    return converted


def _resblock(target: str, name: str, value: torch.Tensor) -> dict[str, torch.Tensor]:
    """One residual-attention-block tensor in transformers naming (fused q/k/v split in three)."""
    if name in ("attn.in_proj_weight", "attn.in_proj_bias"):
        kind = name.rsplit("_", 1)[1]
        return {f"{target}self_attn.{part}_proj.{kind}": chunk
                for part, chunk in zip("qkv", value.chunk(3, dim=0))}
    for old, new in _RESBLOCK_PARTS.items():
        if name.startswith(old):
            return {target + new + name[len(old):]: value}
    return {target + name: value}


def _empty_parts(config: Zero123Config) -> dict[str, Callable[[], torch.nn.Module]]:
    """Builders of each part without initialised weights, for ``load_state_dict(assign=True)``.

    UNet, VAE and projection are built on ``meta``; the CLIP tower on the CPU because it owns a
    non-persistent ``position_ids`` buffer that no checkpoint holds.
    """

    def on_meta(build: Callable[[], torch.nn.Module]) -> Callable[[], torch.nn.Module]:
        def built() -> torch.nn.Module:
            with torch.device("meta"):
                return build()

        return built

    return {
        "unet": on_meta(lambda: UNet2DConditionModel(**config.unet)),
        "vae": on_meta(lambda: AutoencoderKL(**config.vae)),
        "cc_projection": on_meta(lambda: torch.nn.Linear(config.projection_in, config.projection_out)),
        "image_encoder": lambda: CLIPVisionModelWithProjection(CLIPVisionConfig(**config.image_encoder)),
    }
