"""The original single-file (LDM) Zero-1-to-3 checkpoint loader, on a tiny checkpoint written here.

The test renames a tiny diffusers model's weights to the latent-diffusion / OpenAI-CLIP names the
released ``105000.ckpt`` / ``zero123-xl.ckpt`` use (``model.diffusion_model.input_blocks.1.0.in_layers.0``,
``first_stage_model.encoder.down.0.block.0``, ``cond_stage_model.model.visual.transformer.resblocks.0.attn
.in_proj_weight``, ``cc_projection.weight``, ...), saves it with ``torch.save`` as a Lightning-style
``{"state_dict": ..., "global_step": ...}`` and loads it back through the converter.
Reduced: Zero123Config.tiny instead of the full-size architecture.
"""
import re
from types import SimpleNamespace

import pytest
import torch
from diffusers import AutoencoderKL, UNet2DConditionModel
from transformers import CLIPVisionConfig, CLIPVisionModelWithProjection

from idpose_core.model_loading import load_predictor
from idpose_core.zero123 import ModelLoadError, Zero123Config, Zero123Predictor
from idpose_core.zero123.ldm_architecture import config_from_ldm_state

RESNET_LDM = {"norm1": "in_layers.0", "conv1": "in_layers.2", "time_emb_proj": "emb_layers.1",
              "norm2": "out_layers.0", "conv2": "out_layers.3", "conv_shortcut": "skip_connection"}
VAE_ATTENTION_LDM = {"group_norm": "norm", "to_q": "q", "to_k": "k", "to_v": "v", "to_out.0": "proj_out"}
CLIP_LAYER_LDM = {"layer_norm1": "ln_1", "layer_norm2": "ln_2", "mlp.fc1": "mlp.c_fc", "mlp.fc2": "mlp.c_proj",
                  "self_attn.out_proj": "attn.out_proj"}
# The tiny CLIP tower widened to one OpenAI head (width 64): what a file without a config must hold.
OPENAI_CLIP_WIDTH = {"hidden_size": 64, "num_attention_heads": 1}




def rename(name, table):
    """Replace the first dotted component sequence of ``name`` found in ``table``."""
    for new, old in table.items():
        if name.startswith(new + "."):
            return old + name[len(new):]
    return name


def unet_to_ldm(state, layers_per_block):
    """diffusers UNet2DConditionModel names -> openaimodel.UNetModel names (model.diffusion_model.*)."""
    stride = layers_per_block + 1
    fixed = {"time_embedding.linear_1": "time_embed.0", "time_embedding.linear_2": "time_embed.2",
             "conv_in": "input_blocks.0.0", "conv_norm_out": "out.0", "conv_out": "out.2"}
    up_with_attention = {int(k.split(".")[1]) for k in state if re.match(r"up_blocks\.\d+\.attentions", k)}
    out = {}
    for key, value in state.items():
        head, leaf = key.rsplit(".", 1)
        parts = key.split(".")
        if head in fixed:
            name = f"{fixed[head]}.{leaf}"
        elif parts[0] == "down_blocks" and parts[2] == "downsamplers":
            name = f"input_blocks.{(int(parts[1]) + 1) * stride}.0.op.{leaf}"
        elif parts[0] == "up_blocks" and parts[2] == "upsamplers":
            block = int(parts[1])
            position = 2 if block in up_with_attention else 1
            name = f"output_blocks.{block * stride + layers_per_block}.{position}.conv.{leaf}"
        elif parts[0] in ("down_blocks", "up_blocks"):
            block, kind, layer, rest = int(parts[1]), parts[2], int(parts[3]), ".".join(parts[4:])
            index = 1 + block * stride + layer if parts[0] == "down_blocks" else block * stride + layer
            prefix = "input_blocks" if parts[0] == "down_blocks" else "output_blocks"
            name = (f"{prefix}.{index}.0.{rename(rest, RESNET_LDM)}" if kind == "resnets"
                    else f"{prefix}.{index}.1.{rest}")
        elif parts[0] == "mid_block":
            kind, index, rest = parts[1], int(parts[2]), ".".join(parts[3:])
            name = (f"middle_block.{2 * index}.{rename(rest, RESNET_LDM)}" if kind == "resnets"
                    else f"middle_block.1.{rest}")
        else:
            raise AssertionError(f"unmapped UNet key {key}")
        out["model.diffusion_model." + name] = value
    return out


def vae_to_ldm(state, num_blocks):
    """diffusers AutoencoderKL names -> ldm AutoencoderKL names (first_stage_model.*)."""
    out = {}
    for key, value in state.items():
        name = key.replace("conv_norm_out", "norm_out")
        name = re.sub(r"down_blocks\.(\d+)\.resnets\.", r"down.\1.block.", name)
        name = re.sub(r"down_blocks\.(\d+)\.downsamplers\.0\.", r"down.\1.downsample.", name)
        name = re.sub(r"up_blocks\.(\d+)\.resnets\.", lambda m: f"up.{num_blocks - 1 - int(m[1])}.block.", name)
        name = re.sub(r"up_blocks\.(\d+)\.upsamplers\.0\.", lambda m: f"up.{num_blocks - 1 - int(m[1])}.upsample.",
                      name)
        name = re.sub(r"mid_block\.resnets\.(\d+)\.", lambda m: f"mid.block_{int(m[1]) + 1}.", name)
        name = name.replace("conv_shortcut", "nin_shortcut")
        if ".mid_block.attentions.0." in name:
            coder, rest = name.split(".mid_block.attentions.0.")
            name = f"{coder}.mid.attn_1.{rename(rest, VAE_ATTENTION_LDM)}"
            if name.endswith("weight") and value.ndim == 2:
                value = value[:, :, None, None]  # LDM uses 1x1 convolutions
        out["first_stage_model." + name] = value
    return out


def clip_to_openai(state):
    """transformers CLIPVisionModelWithProjection names -> OpenAI CLIP visual names (fused q/k/v)."""
    out = {}
    prefix = "cond_stage_model.model.visual."
    for key, value in state.items():
        name = key.removeprefix("vision_model.")
        layer = re.match(r"encoder\.layers\.(\d+)\.(.+)", name)
        if key == "visual_projection.weight":
            out[prefix + "proj"] = value.t().contiguous()
        elif layer and layer[2].startswith("self_attn.q_proj."):
            kind = layer[2].rsplit(".", 1)[1]
            base = f"encoder.layers.{layer[1]}.self_attn."
            fused = torch.cat([state[f"vision_model.{base}{p}_proj.{kind}"] for p in "qkv"])
            out[f"{prefix}transformer.resblocks.{layer[1]}.attn.in_proj_{kind}"] = fused
        elif layer and re.match(r"self_attn\.[kv]_proj\.", layer[2]):
            continue
        elif layer:
            out[f"{prefix}transformer.resblocks.{layer[1]}.{rename(layer[2], CLIP_LAYER_LDM)}"] = value
        else:
            name = {"embeddings.class_embedding": "class_embedding",
                    "embeddings.patch_embedding.weight": "conv1.weight",
                    "embeddings.position_embedding.weight": "positional_embedding"}.get(name, name)
            out[prefix + name.replace("pre_layrnorm", "ln_pre").replace("post_layernorm", "ln_post")] = value
    return out


def ldm_state_dict(modules, config=None):
    """The parts of ``modules`` (built from ``config``, default the tiny one) under the original release's names."""
    config = config or Zero123Config.tiny()
    state = {}
    state.update(unet_to_ldm(modules.unet.state_dict(), config.unet["layers_per_block"]))
    state.update(vae_to_ldm(modules.vae.state_dict(), len(config.vae["block_out_channels"])))
    state.update(clip_to_openai(modules.image_encoder.state_dict()))
    state.update({f"cc_projection.{k}": v for k, v in modules.cc_projection.state_dict().items()})
    # The released files also carry the unused CLIP text tower's leftovers.
    state["cond_stage_model.model.token_embedding.weight"] = torch.zeros(8, 4)
    state["cond_stage_model.model.logit_scale"] = torch.tensor(4.6)
    return {key: value.clone() for key, value in state.items()}


@pytest.fixture(scope="module")
def source():
    return Zero123Predictor.tiny(seed=7)


@pytest.fixture(scope="module")
def checkpoint(source, tmp_path_factory):
    file = tmp_path_factory.mktemp("ldm") / "zero123-tiny.ckpt"
    torch.save({"state_dict": ldm_state_dict(source.modules), "global_step": 105000, "epoch": 3}, file)
    return file


def assert_same_weights(loaded, source):
    for name in ("unet", "vae", "image_encoder", "cc_projection"):
        got, expected = (getattr(p.modules, name).state_dict() for p in (loaded, source))
        assert got.keys() == expected.keys(), name
        for key in expected:
            torch.testing.assert_close(got[key], expected[key], rtol=0, atol=0, msg=f"{name}.{key}")


def test_uses_the_original_key_names(checkpoint):
    keys = torch.load(checkpoint, weights_only=True)["state_dict"].keys()
    for expected in ("model.diffusion_model.input_blocks.1.0.in_layers.0.weight",
                     "model.diffusion_model.output_blocks.2.1.conv.weight",
                     "first_stage_model.encoder.mid.attn_1.q.weight",
                     "cond_stage_model.model.visual.transformer.resblocks.0.attn.in_proj_weight",
                     "cond_stage_model.model.visual.proj", "cc_projection.weight"):
        assert expected in keys


def test_checkpoint_loads_into_identical_modules(source, checkpoint, errors_of):
    loaded = Zero123Predictor.from_ldm_checkpoint(checkpoint, device="cpu", config=Zero123Config.tiny())
    assert_same_weights(loaded, source)
    torch.testing.assert_close(errors_of(loaded), errors_of(source), rtol=0, atol=0)


def test_bare_state_dict_in_safetensors(source, tmp_path, errors_of):
    from safetensors.torch import save_file

    file = tmp_path / "zero123-tiny.safetensors"
    save_file({k: v.contiguous() for k, v in ldm_state_dict(source.modules).items()}, file)
    loaded = Zero123Predictor.from_ldm_checkpoint(file, config=Zero123Config.tiny())
    torch.testing.assert_close(errors_of(loaded), errors_of(source), rtol=0, atol=0)


def test_ema_weights_on_request(source, tmp_path):
    """LDM keeps an EMA UNet under flattened names (model_ema.diffusion_modelinput_blocks00weight)."""
    state = ldm_state_dict(source.modules)
    ema = {"model_ema." + k[len("model."):].replace(".", ""): v + 1.0 for k, v in state.items()
           if k.startswith("model.diffusion_model.")}
    file = tmp_path / "with-ema.ckpt"
    torch.save({"state_dict": {**state, **ema}}, file)
    plain = Zero123Predictor.from_ldm_checkpoint(file, config=Zero123Config.tiny())
    averaged = Zero123Predictor.from_ldm_checkpoint(file, config=Zero123Config.tiny(), use_ema=True)
    conv_in = source.modules.unet.conv_in.weight
    torch.testing.assert_close(plain.modules.unet.conv_in.weight, conv_in, rtol=0, atol=0)
    torch.testing.assert_close(averaged.modules.unet.conv_in.weight, conv_in + 1.0, rtol=0, atol=0)


def test_released_shapes_read_as_the_full_size_architecture():
    """A released file (here its shapes alone, on the meta device) loads into exactly Zero123Config.full()."""
    config = Zero123Config.full()
    with torch.device("meta"):
        parts = SimpleNamespace(unet=UNet2DConditionModel(**config.unet), vae=AutoencoderKL(**config.vae),
                                image_encoder=CLIPVisionModelWithProjection(CLIPVisionConfig(**config.image_encoder)),
                                cc_projection=torch.nn.Linear(config.projection_in, config.projection_out))
    assert config_from_ldm_state(ldm_state_dict(parts, config)) == config


def save_ldm(config, file, seed=5):
    """A random model of ``config`` saved under the original names; returns the model."""
    model = Zero123Predictor.random(config, seed)
    torch.save({"state_dict": ldm_state_dict(model.modules, config)}, file)
    return model


def test_load_predictor_reads_a_reduced_architecture(tmp_path, errors_of):
    """Without a config, the widths come from the file: a narrow file loads by its path alone."""
    config = Zero123Config.tiny().updated(image_encoder=OPENAI_CLIP_WIDTH)
    source = save_ldm(config, tmp_path / "narrow.ckpt")
    loaded = load_predictor(str(tmp_path / "narrow.ckpt"), device="cpu")
    assert_same_weights(loaded, source)
    torch.testing.assert_close(errors_of(loaded), errors_of(source), rtol=0, atol=0)


def test_an_explicit_config_the_file_does_not_fit_is_named(checkpoint):
    with pytest.raises(ModelLoadError, match="do not match the Zero-1-to-3 shapes") as caught:
        Zero123Predictor.from_ldm_checkpoint(checkpoint, device="cpu", config=Zero123Config.full())
    assert str(checkpoint) in str(caught.value)


def test_a_clip_tower_without_a_whole_head_needs_a_config(checkpoint):
    """Heads are in no tensor: OpenAI's rule (width // 64) gives none for the tiny 32-wide tower."""
    with pytest.raises(ModelLoadError, match="needs an explicit Zero123Config") as caught:
        load_predictor(str(checkpoint), device="cpu")
    assert str(checkpoint) in str(caught.value)


def test_parts_that_do_not_fit_are_refused(tmp_path):
    """A UNet without the reference-latent channels (4 in, as Stable Diffusion's) is no Zero-1-to-3."""
    config = Zero123Config.tiny().updated(image_encoder=OPENAI_CLIP_WIDTH, unet={"in_channels": 4})
    save_ldm(config, tmp_path / "sd.ckpt")
    with pytest.raises(ModelLoadError, match="parts do not fit together: unet in_channels 4"):
        load_predictor(str(tmp_path / "sd.ckpt"), device="cpu")


def test_missing_parts_are_named(source, tmp_path):
    state = {k: v for k, v in ldm_state_dict(source.modules).items() if not k.startswith("cond_stage_model.")}
    file = tmp_path / "no-clip.ckpt"
    torch.save({"state_dict": state}, file)
    with pytest.raises(ValueError, match="no cond_stage_model.model.visual weights"):
        Zero123Predictor.from_ldm_checkpoint(file, config=Zero123Config.tiny())
