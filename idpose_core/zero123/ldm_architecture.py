"""The architecture of an LDM (single-file) Zero-1-to-3 checkpoint, read from its tensor shapes.

Why shapes: the original release is one file without a config, and a narrower model built with the
official code (the reduced checkpoint that pins the fidelity to the official implementation) has to load
the same way, by its path alone. The released files give exactly ``Zero123Config.full()``. What no tensor
holds keeps the released (official yaml) value: the UNet's 8 attention heads and sample size, the VAE's
scale factor 0.18215 and sample size, the schedule; the CLIP tower has width // 64 heads, the rule of
OpenAI's ``clip.model.CLIP`` that built it.
"""
from __future__ import annotations

import re
from collections.abc import Mapping
from math import isqrt
from typing import Any

import torch

from idpose_core.zero123.config import Zero123Config

UNET_PREFIX = "model.diffusion_model."
VAE_PREFIX = "first_stage_model."
CLIP_PREFIX = "cond_stage_model.model.visual."
CLIP_HEAD_WIDTH = 64


def config_from_ldm_state(state: Mapping[str, torch.Tensor]) -> Zero123Config:
    """The ``Zero123Config`` whose parts the LDM ``state`` fits; ``ValueError`` names what is missing or odd."""
    return Zero123Config.full().updated(unet=unet_shapes(state), vae=vae_shapes(state),
                                        image_encoder=clip_shapes(state))


def unet_shapes(state: Mapping[str, torch.Tensor]) -> dict[str, Any]:
    """``UNet2DConditionModel`` kwargs from ``openaimodel.UNetModel`` tensors: widths, levels, attention."""
    blocks = _indices(state, UNET_PREFIX, r"input_blocks\.(\d+)\.")
    levels: list[list[int]] = [[]]
    for block in blocks[1:]:  # block 0 is the input convolution; a strided "op" convolution starts a level
        if f"{UNET_PREFIX}input_blocks.{block}.0.op.weight" in state:
            levels.append([])
        else:
            levels[-1].append(block)
    layers = {len(level) for level in levels}
    if len(layers) != 1 or 0 in layers:
        raise ValueError(f"UNet levels with different numbers of blocks: {levels}")
    attention = [f"{UNET_PREFIX}input_blocks.{level[0]}.1.proj_in.weight" in state for level in levels]
    return {
        "in_channels": _shape(state, UNET_PREFIX + "input_blocks.0.0.weight")[1],
        "out_channels": _shape(state, UNET_PREFIX + "out.2.weight")[0],
        "block_out_channels": tuple(_shape(state, f"{UNET_PREFIX}input_blocks.{level[0]}.0.out_layers.3.weight")[0]
                                    for level in levels),
        "layers_per_block": layers.pop(),
        "down_block_types": tuple("CrossAttnDownBlock2D" if has else "DownBlock2D" for has in attention),
        "up_block_types": tuple("CrossAttnUpBlock2D" if has else "UpBlock2D" for has in reversed(attention)),
        "cross_attention_dim": _shape(state, UNET_PREFIX + "middle_block.1.transformer_blocks.0.attn2.to_k.weight")[1],
    }


def vae_shapes(state: Mapping[str, torch.Tensor]) -> dict[str, Any]:
    """``AutoencoderKL`` kwargs from the LDM autoencoder's tensors: widths, levels, latent channels."""
    levels = _indices(state, VAE_PREFIX, r"encoder\.down\.(\d+)\.")
    blocks = _indices(state, VAE_PREFIX, r"encoder\.down\.0\.block\.(\d+)\.")
    if not levels or not blocks:
        raise ValueError(f"no {VAE_PREFIX}encoder.down.* blocks")
    return {
        "in_channels": _shape(state, VAE_PREFIX + "encoder.conv_in.weight")[1],
        "out_channels": _shape(state, VAE_PREFIX + "decoder.conv_out.weight")[0],
        "block_out_channels": tuple(_shape(state, f"{VAE_PREFIX}encoder.down.{level}.block.0.conv2.weight")[0]
                                    for level in levels),
        "layers_per_block": len(blocks),
        "down_block_types": ("DownEncoderBlock2D",) * len(levels),
        "up_block_types": ("UpDecoderBlock2D",) * len(levels),
        "latent_channels": _shape(state, VAE_PREFIX + "quant_conv.weight")[0] // 2,
    }


def clip_shapes(state: Mapping[str, torch.Tensor]) -> dict[str, Any]:
    """``CLIPVisionConfig`` kwargs from OpenAI CLIP ``visual.*`` tensors (heads = width // 64, as OpenAI's)."""
    width, _, patch, _ = _shape(state, CLIP_PREFIX + "conv1.weight")
    tokens = _shape(state, CLIP_PREFIX + "positional_embedding")[0]
    grid = isqrt(tokens - 1)
    if grid * grid != tokens - 1:
        raise ValueError(f"CLIP positional embedding of {tokens} tokens is not 1 + a square grid")
    if width < CLIP_HEAD_WIDTH:
        raise ValueError(f"CLIP width {width} < {CLIP_HEAD_WIDTH}: an OpenAI CLIP tower has width // "
                         f"{CLIP_HEAD_WIDTH} attention heads, so this one needs an explicit Zero123Config")
    return {
        "hidden_size": width,
        "intermediate_size": _shape(state, CLIP_PREFIX + "transformer.resblocks.0.mlp.c_fc.weight")[0],
        "projection_dim": _shape(state, CLIP_PREFIX + "proj")[1],
        "num_hidden_layers": len(_indices(state, CLIP_PREFIX, r"transformer\.resblocks\.(\d+)\.")),
        "num_attention_heads": width // CLIP_HEAD_WIDTH,
        "image_size": grid * patch,
        "patch_size": patch,
    }


def _indices(state: Mapping[str, torch.Tensor], prefix: str, pattern: str) -> list[int]:
    """The sorted distinct integers that ``pattern``'s group captures in the keys after ``prefix``."""
    compiled = re.compile(re.escape(prefix) + pattern)
    return sorted({int(found.group(1)) for key in state if (found := compiled.match(key))})


def _shape(state: Mapping[str, torch.Tensor], key: str) -> tuple[int, ...]:
    if key not in state:
        raise ValueError(f"no tensor {key}")
    return tuple(state[key].shape)
