"""Reference outputs of the OFFICIAL ID-Pose code on a reduced Zero-1-to-3, for ``test/test_official_fidelity.py``.

Usage, in a venv of its own with the official code's dependencies (``scripts/official_fixture_requirements.txt``
says how to make it):

    python scripts/make_official_fixture.py /path/to/id-pose-checkout [--out test/data/official_fidelity]

Nothing of the official repository is copied here: its modules are imported from the checkout given.
The script builds the official ``LatentDiffusion`` from its yaml
(``src/configs/sd-objaverse-finetune-c_concat-256.yaml``) with reduced widths (``UNET``, ``VAE``, ``CLIP``
below; everything else as the yaml says), draws seeded random weights, saves them as an original-style
LDM checkpoint (``{"state_dict": ...}`` with the official key names, tensors only), loads that file into a
fresh official model and runs the official loss path on fixed inputs: per sample the step of
``pose_funcs.find_optimal_poses`` (``create_pose_params`` -> ``PoseT`` -> ``shared_step(batch, ts=...)`` ->
``backward``) with the fixed noise ``pose_funcs.noise_loss`` passes. It records what the official
``DiffusionWrapper`` receives and gives (``c_crossattn``, ``c_concat``, ``eps_hat``; a forward hook), the
scaled target latent ``get_input`` returns, the loss, its gradient w.r.t. the pose, and
``pose_funcs.noise_loss`` itself (``loss_sampled``).

Patches, all made here and none in the checkout:

- ``clip.load`` returns a reduced OpenAI ``clip.model.CLIP`` (ViT, width 64, 2 layers, patch 14, 48-d
  embedding; heads by OpenAI's own rule width // 64) instead of downloading ViT-L/14; its weights are
  drawn with the rest. ``FrozenCLIPImageEmbedder`` keeps its own preprocessing (kornia bicubic resize to
  224 px, CLIP mean / std).
- ``LatentDiffusion`` hard-codes ``cc_projection = Linear(772, 768)`` (ViT-L/14's 768-d embedding + 4
  pose features -> the UNet's 768-d context); it is replaced by ``Linear(48 + 4, 64)`` to fit the reduced
  CLIP and UNet.
- ``torchvision`` is stubbed: the official code imports it only for image logging and ``clip`` for its PIL
  preprocessing, both unused here, and the PyPI torchvision wheels do not load beside a CPU-only torch build.
- While the reference is computed, ``DiagonalGaussianDistribution.sample`` returns the mode: the official
  loss noises a SAMPLE of the VAE posterior of the target, the project its mode (deterministic). The
  official sampled loss is recorded beside it (``loss_sampled``, seeded).
- ``use_ema: False``: no EMA copy of the UNet in the file (it is not on the loss path).
"""
from __future__ import annotations

import argparse
import contextlib
import subprocess
import sys
import types
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from safetensors.torch import save_file

CONFIG = "src/configs/sd-objaverse-finetune-c_concat-256.yaml"
OUT = Path(__file__).resolve().parents[1] / "test" / "data" / "official_fidelity"
CHECKPOINT, REFERENCE = "zero123-reduced.ckpt", "reference.safetensors"

# Overrides of the yaml's unet_config / first_stage_config.ddconfig: 32 channels (the least GroupNorm(32)
# takes), two levels, one block per level (a 3 MB checkpoint). Kept from the yaml: 8 input / 4 output
# channels, 8 heads, spatial transformers of depth 1, attention on every level but the last, the VAE's
# 4 latent channels and scale factor 0.18215, the schedule.
UNET = {"image_size": 16, "model_channels": 32, "channel_mult": [1, 1], "num_res_blocks": 1,
        "attention_resolutions": [1], "context_dim": 64}
VAE = {"ch": 32, "ch_mult": [1, 1], "num_res_blocks": 1, "resolution": 32}
CLIP = {"embed_dim": 48, "image_resolution": 224, "vision_layers": 2, "vision_width": 64, "vision_patch_size": 14,
        "context_length": 4, "vocab_size": 8, "transformer_width": 8, "transformer_heads": 1, "transformer_layers": 1}
POSE_FEATURES = 4

IMAGE_SIZE = 32
# Samples: (reference view, target view, pose (d_polar, d_azimuth, d_radius), step t). The poses are away from
# stationary points of the loss: a gradient near zero is mostly round-off, which no relative tolerance pins.
SAMPLES = [(0, 1, (0.35, 1.2, 0.1), 200), (0, 1, (0.35, 1.2, 0.1), 700),
           (1, 0, (-0.4, 5.0, -0.1), 200), (1, 0, (-0.4, 5.0, -0.1), 700)]

WEIGHT_SEED, INPUT_SEED, POSTERIOR_SEED = 0, 1, 2


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkout", type=Path, help="a checkout of the official ID-Pose repository")
    parser.add_argument("--out", type=Path, default=OUT, help=f"output folder (default {OUT})")
    args = parser.parse_args()
    checkout = args.checkout.resolve()
    official = import_official(checkout)
    args.out.mkdir(parents=True, exist_ok=True)

    torch.manual_seed(WEIGHT_SEED)
    model = build_model(official, checkout)
    randomise_(model, WEIGHT_SEED)
    torch.save({"state_dict": {key: value.clone() for key, value in model.state_dict().items()}},
               args.out / CHECKPOINT)

    model = build_model(official, checkout)
    state = torch.load(args.out / CHECKPOINT, map_location="cpu", weights_only=True)["state_dict"]
    model.load_state_dict(state, strict=True)
    model.eval()
    reference = compute_reference(official, model)
    metadata = {"official_commit": official_commit(checkout), "config": CONFIG,
                "generator": "scripts/make_official_fixture.py"}
    save_file(reference, str(args.out / REFERENCE), metadata=metadata)
    for name, value in reference.items():
        print(f"{name:>14} {tuple(value.shape)}")
    print("wrote", *(args.out / name for name in (CHECKPOINT, REFERENCE)))


def import_official(checkout: Path) -> types.SimpleNamespace:
    """The official modules this script uses, imported from ``checkout`` after the patches above."""
    if not (checkout / CONFIG).is_file():
        raise SystemExit(f"{checkout} is not an ID-Pose checkout: no {CONFIG}")
    import pytorch_lightning  # noqa: F401 - before the stub, so torchmetrics records torchvision as absent

    stub_torchvision()
    import clip
    import clip.model

    clip.load = lambda *args, **kwargs: (clip.model.CLIP(**CLIP).float(), None)
    sys.path.insert(0, str(checkout))
    from omegaconf import OmegaConf
    from src.ldm.modules.distributions.distributions import DiagonalGaussianDistribution
    from src.ldm.util import instantiate_from_config
    from src.pose_funcs import PoseT, create_pose_params, noise_loss

    return types.SimpleNamespace(OmegaConf=OmegaConf, instantiate_from_config=instantiate_from_config,
                                 DiagonalGaussianDistribution=DiagonalGaussianDistribution, PoseT=PoseT,
                                 create_pose_params=create_pose_params, noise_loss=noise_loss)


def stub_torchvision() -> None:
    """Empty ``torchvision``, ``torchvision.transforms`` and ``torchvision.utils`` whose names raise if called."""

    def unavailable(name: str) -> Callable[..., Any]:
        def call(*args: Any, **kwargs: Any) -> Any:
            raise RuntimeError(f"torchvision.{name} is stubbed by make_official_fixture.py")

        return call

    names = {"transforms": ("Compose", "Resize", "CenterCrop", "ToTensor", "Normalize"), "utils": ("make_grid",)}
    root = types.ModuleType("torchvision")
    sys.modules["torchvision"] = root
    for module_name, attributes in names.items():
        module = types.ModuleType(f"torchvision.{module_name}")
        for attribute in attributes:
            setattr(module, attribute, unavailable(f"{module_name}.{attribute}"))
        setattr(root, module_name, module)
        sys.modules[module.__name__] = module


def build_model(official: types.SimpleNamespace, checkout: Path) -> torch.nn.Module:
    """The official ``LatentDiffusion`` from its yaml with the reduced widths (random weights)."""
    config = official.OmegaConf.load(checkout / CONFIG)
    params = config.model.params
    params.unet_config.params.update(UNET)
    params.first_stage_config.params.ddconfig.update(VAE)
    params.use_ema = False
    model = official.instantiate_from_config(config.model)
    model.cc_projection = torch.nn.Linear(CLIP["embed_dim"] + POSE_FEATURES, UNET["context_dim"])
    return model


def randomise_(model: torch.nn.Module, seed: int) -> None:
    """Seeded weights everywhere (the official init zeroes the UNet's output layers, so eps_hat would be 0).

    Matrices and kernels ~ N(0, 1 / fan_in); norm scales 1 + N(0, 0.1^2); other vectors N(0, 0.1^2); scalars
    (CLIP's unused logit scale) keep their value.
    """
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for name, parameter in sorted(model.named_parameters()):
            noise = torch.randn(parameter.shape, generator=generator)
            if parameter.ndim >= 2:
                parameter.copy_(noise / parameter[0].numel() ** 0.5)
            elif parameter.ndim == 1:
                parameter.copy_(1 + 0.1 * noise if name.endswith("weight") else 0.1 * noise)


def fixed_inputs() -> tuple[torch.Tensor, torch.Tensor]:
    """Two smooth seeded images (2, 3, S, S) in (-1, 1) and one noise (4, h, w) per sample."""
    generator = torch.Generator().manual_seed(INPUT_SEED)
    coarse = torch.randn(2, 3, 4, 4, generator=generator)
    images = torch.tanh(1.5 * F.interpolate(coarse, size=(IMAGE_SIZE, IMAGE_SIZE), mode="bicubic", align_corners=True))
    latent = IMAGE_SIZE // 2 ** (len(VAE["ch_mult"]) - 1)
    noise = torch.randn(len(SAMPLES), 4, latent, latent, generator=generator)
    return images, noise


@contextlib.contextmanager
def posterior_mode(official: types.SimpleNamespace) -> Iterator[None]:
    """Make the official VAE posterior's ``sample()`` return its mode (the project's target latent)."""
    distribution = official.DiagonalGaussianDistribution
    sample = distribution.sample
    distribution.sample = distribution.mode
    try:
        yield
    finally:
        distribution.sample = sample


def compute_reference(official: types.SimpleNamespace, model: torch.nn.Module) -> dict[str, torch.Tensor]:
    """Inputs and official results per sample: conditioning, target latent, eps_hat, loss, pose gradient.

    ``loss`` and everything it depends on use the posterior mode for the target latent; ``loss_sampled`` is
    the official ``noise_loss`` (a posterior sample, seeded). ``c_crossattn`` / ``c_concat`` are what the
    official ``DiffusionWrapper`` receives, ``target_latent`` the scaled latent ``get_input`` returns.
    """
    images, noise = fixed_inputs()
    views = [image[None].permute(0, 2, 3, 1) for image in images]  # (1, H, W, 3), as estimate_poses passes them
    seen: dict[str, torch.Tensor] = {}

    def unet_call(module: torch.nn.Module, args: tuple, kwargs: dict, output: torch.Tensor) -> None:
        seen.update(t=args[1], eps_hat=output[0], c_concat=kwargs["c_concat"][0][0],
                    c_crossattn=kwargs["c_crossattn"][0][0])

    def get_input(*args: Any, **kwargs: Any) -> list:
        out = type(model).get_input(model, *args, **kwargs)
        seen["target_latent"] = out[0][0]
        return out

    hook = model.model.register_forward_hook(unet_call, with_kwargs=True)
    model.get_input = get_input
    results: dict[str, list[torch.Tensor]] = {}
    for index, (ref, tgt, pose, t) in enumerate(SAMPLES):
        sample_noise = noise[index:index + 1]
        with posterior_mode(official):
            params = official.create_pose_params(list(pose), model.device)
            batch = {"image_cond": views[ref], "image_target": views[tgt],
                     "T": official.PoseT()(torch.cat(params)[None, ...])}
            loss, _ = model.shared_step(batch, ts=np.array([t / 1000]), noise=sample_noise)
            loss.backward()
        if seen["t"].tolist() != [t]:
            raise RuntimeError(f"the official model ran at t = {seen['t'].tolist()}, expected {t}")
        seen.update(loss=loss, pose_grad=torch.cat([param.grad for param in params]))
        for name in ("c_crossattn", "c_concat", "target_latent", "eps_hat", "loss", "pose_grad"):
            results.setdefault(name, []).append(seen[name].detach().clone())
        torch.manual_seed(POSTERIOR_SEED + index)
        results.setdefault("loss_sampled", []).append(torch.tensor(official.noise_loss(
            model, views[ref], views[tgt], torch.tensor([pose]), [t / 1000, (t + 1) / 1000], 1,
            noise=sample_noise.numpy()), dtype=torch.float32))
    hook.remove()
    del model.get_input
    return {
        "images": images, "noise": noise,
        "ref": torch.tensor([s[0] for s in SAMPLES]), "tgt": torch.tensor([s[1] for s in SAMPLES]),
        "pose": torch.tensor([s[2] for s in SAMPLES], dtype=torch.float32), "t": torch.tensor([s[3] for s in SAMPLES]),
        **{name: torch.stack(values) for name, values in results.items()},
    }


def official_commit(checkout: Path) -> str:
    """The checkout's git commit, or "unknown" for an unpacked archive."""
    result = subprocess.run(["git", "-C", str(checkout), "rev-parse", "HEAD"], capture_output=True, text=True)
    return result.stdout.strip() if result.returncode == 0 else "unknown"


if __name__ == "__main__":
    main()
