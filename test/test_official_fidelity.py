"""Fidelity to the official ID-Pose code, pinned: a reduced Zero-1-to-3 whose outputs the official code computed.

``test/data/official_fidelity/`` is what ``scripts/make_official_fixture.py`` wrote from a checkout of the
official repository (xt4d/id-pose, commit in the reference's metadata): its ``LatentDiffusion`` built from
its yaml with reduced widths and seeded random weights, saved as an original-style LDM checkpoint, and the
official results on fixed inputs (two 32 px images, two poses, t = 200 and 700, fixed noise): the
conditioning its UNet received, the target latent, eps_hat, the loss (target latent = posterior mode, as
here) and the loss's gradient w.r.t. the pose. ``load_predictor``, the path a user takes, must reproduce
every one within 1e-5 relative, per sample.
"""
from pathlib import Path

import pytest
import torch
from safetensors.torch import load_file

from idpose_core.model_loading import load_predictor
from idpose_core.zero123 import Zero123Predictor

DATA = Path(__file__).parent / "data" / "official_fidelity"
CHECKPOINT = DATA / "zero123-reduced.ckpt"
TOLERANCE = 1e-5
OUTPUTS = ("c_crossattn", "c_concat", "target_latent", "eps_hat", "loss", "pose_grad")


@pytest.fixture(scope="module")
def reference():
    return load_file(DATA / "reference.safetensors")


@pytest.fixture(scope="module")
def predictor():
    return load_predictor(str(CHECKPOINT), device="cpu", precision="float32")


def run(predictor, reference, pose):
    """The project's results on the reference inputs at ``pose``: what its UNet got and gave, loss, gradient."""
    seen = {}

    def unet_call(module, args, kwargs, output):
        seen.update(c_concat=args[0][:, 4:], c_crossattn=kwargs["encoder_hidden_states"], eps_hat=output.sample)

    views = predictor.encode(reference["images"])
    pose = pose.clone().requires_grad_(True)
    hook = predictor.modules.unet.register_forward_hook(unet_call, with_kwargs=True)
    try:
        loss = predictor.noise_error(views, reference["ref"], reference["tgt"], pose, reference["t"],
                                     reference["noise"])
    finally:
        hook.remove()
    loss.sum().backward()
    results = {name: value.detach() for name, value in seen.items()}
    return {**results, "target_latent": views.latents[reference["tgt"]], "loss": loss.detach(), "pose_grad": pose.grad}


def relative(got, expected):
    """Per sample ||got - expected|| / ||expected||."""
    got, expected = got.reshape(len(expected), -1), expected.reshape(len(expected), -1)
    return (got - expected).norm(dim=1) / expected.norm(dim=1)


@pytest.fixture(scope="module")
def project(predictor, reference):
    return run(predictor, reference, reference["pose"])


def test_the_checkpoint_is_an_original_style_reduced_file(predictor):
    state = torch.load(CHECKPOINT, map_location="cpu", weights_only=True)["state_dict"]
    for prefix in ("model.diffusion_model.", "first_stage_model.", "cond_stage_model.model.visual.", "cc_projection."):
        assert any(key.startswith(prefix) for key in state), prefix
    assert isinstance(predictor, Zero123Predictor)
    assert predictor.modules.unet.config.block_out_channels == (32, 32)
    assert predictor.modules.image_encoder.config.hidden_size == 64


def test_the_reference_covers_both_timesteps_and_both_poses(reference):
    cases = {(tuple(pose.tolist()), int(t)) for pose, t in zip(reference["pose"], reference["t"])}
    poses = {pose for pose, _ in cases}
    assert len(poses) == 2 and cases == {(pose, t) for pose in poses for t in (200, 700)}


@pytest.mark.parametrize("name", OUTPUTS)
def test_every_output_matches_the_official_code(project, reference, name):
    errors = relative(project[name], reference[name])
    assert errors.max() <= TOLERANCE, f"{name}: relative errors per sample {errors.tolist()}"


def test_a_perturbed_pose_misses_the_reference(predictor, reference):
    """The check can fail: 0.1 along the official gradient moves the loss far beyond the tolerance."""
    step = reference["pose_grad"] / reference["pose_grad"].norm(dim=1, keepdim=True)
    moved = run(predictor, reference, reference["pose"] + 0.1 * step)
    assert relative(moved["loss"], reference["loss"]).min() > 10 * TOLERANCE


def test_the_official_posterior_sample_would_miss_the_reference(reference):
    """The official loss noises a sample of the target's VAE posterior, the project (and the reference) its mode."""
    assert relative(reference["loss_sampled"], reference["loss"]).min() > TOLERANCE
