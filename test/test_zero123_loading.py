"""Loading Zero-1-to-3 from a diffusers folder and through load_predictor; every bad path -> ModelLoadError.

Reduced: the tiny random model (Zero123Config.tiny) stands in for the released weights.
"""
import argparse
import io
import json
import pickle
import random
import shutil
import zipfile

import pytest
import torch
from diffusers import UNet2DConditionModel
from safetensors.torch import load_file, save_file

from idpose_core.model_loading import load_predictor
from idpose_core.zero123 import ModelLoadError, Zero123Config, Zero123Predictor


@pytest.fixture(scope="module")
def source():
    return Zero123Predictor.tiny(seed=3)


@pytest.fixture(scope="module")
def saved(source, tmp_path_factory):
    folder = tmp_path_factory.mktemp("zero123-tiny")
    source.save_pretrained(folder)
    return folder


@pytest.fixture
def copy(saved, tmp_path):
    """A scratch copy of the saved folder that a test may damage."""
    return shutil.copytree(saved, tmp_path / "model")


def test_layout_on_disk(saved):
    expected = {"unet", "vae", "image_encoder", "cc_projection", "feature_extractor", "scheduler", "model_index.json"}
    assert expected <= {p.name for p in saved.iterdir()}
    assert not list(saved.rglob("*.bin")) and list(saved.rglob("*.safetensors"))
    assert json.loads((saved / "cc_projection" / "config.json").read_text())["in_channel"] == 36
    assert set(load_file(saved / "cc_projection" / "diffusion_pytorch_model.safetensors")) == {
        "projection.weight", "projection.bias"}


def test_round_trip_gives_identical_outputs(source, saved, errors_of):
    loaded = Zero123Predictor.from_pretrained(saved, device="cpu")
    torch.testing.assert_close(errors_of(loaded), errors_of(source), rtol=0, atol=0)
    assert loaded.modules.scheduler.config.beta_schedule == "scaled_linear"


def test_load_predictor_dispatches_a_folder(source, saved, errors_of):
    predictor = load_predictor(str(saved), device="cpu", precision="float32")
    assert isinstance(predictor, Zero123Predictor) and predictor.dtype == torch.float32
    torch.testing.assert_close(errors_of(predictor), errors_of(source), rtol=0, atol=0)


def test_bfloat16_precision_runs_close_to_float32(source, saved, errors_of):
    predictor = load_predictor(str(saved), device="cpu", precision="bfloat16")
    assert predictor.modules.unet.dtype == torch.bfloat16
    # what runs once per view, and the pose path, keep float32
    assert predictor.modules.vae.dtype == predictor.modules.image_encoder.dtype == torch.float32
    assert predictor.modules.cc_projection.weight.dtype == torch.float32
    views = predictor.encode(torch.zeros(1, 3, 64, 64))
    assert views.conditioning["image_embeds"].dtype == torch.float32
    assert predictor.pose_tokens(views.conditioning["image_embeds"], torch.zeros(1, 3)).dtype == torch.float32
    torch.testing.assert_close(errors_of(predictor), errors_of(source), rtol=0.1, atol=0.05)


def test_clip_camera_projection_layout_loads(source, copy, errors_of):
    """The bennyguo/ashawkey conversions name the projection folder and its Linear differently."""
    weights = load_file(copy / "cc_projection" / "diffusion_pytorch_model.safetensors")
    shutil.rmtree(copy / "cc_projection")
    (copy / "clip_camera_projection").mkdir()
    (copy / "clip_camera_projection" / "config.json").write_text(
        json.dumps({"_class_name": "CLIPCameraProjection", "embedding_dim": 32, "additional_embeddings": 4}))
    save_file({k.replace("projection.", "proj."): v for k, v in weights.items()},
              copy / "clip_camera_projection" / "diffusion_pytorch_model.safetensors")
    torch.testing.assert_close(errors_of(Zero123Predictor.from_pretrained(copy)), errors_of(source), rtol=0, atol=0)


def test_projection_in_a_weights_only_pickle_loads(source, copy, errors_of):
    """Older conversions ship diffusion_pytorch_model.bin; it is read with weights_only=True."""
    file = copy / "cc_projection" / "diffusion_pytorch_model.safetensors"
    torch.save(load_file(file), copy / "cc_projection" / "diffusion_pytorch_model.bin")
    file.unlink()
    torch.testing.assert_close(errors_of(Zero123Predictor.from_pretrained(copy)), errors_of(source), rtol=0, atol=0)


def expect_error(path, *fragments):
    with pytest.raises(ModelLoadError) as caught:
        load_predictor(str(path), device="cpu")
    message = str(caught.value)
    assert str(path) in message and "huggingface-cli download" in message
    for fragment in fragments:
        assert fragment in message, message


def test_missing_folder(tmp_path):
    expect_error(tmp_path / "nowhere", "no such folder or file")


def test_missing_part(copy):
    shutil.rmtree(copy / "vae")
    shutil.rmtree(copy / "cc_projection")
    expect_error(copy, "missing part(s) vae, cc_projection")


def test_missing_weight_file(copy):
    (copy / "unet" / "diffusion_pytorch_model.safetensors").unlink()
    expect_error(copy, "cannot load part 'unet'")


def test_missing_weight_tensor_is_not_silently_initialised(copy):
    file = copy / "image_encoder" / "model.safetensors"
    weights = load_file(file)
    del weights["visual_projection.weight"]
    save_file(weights, file, metadata={"format": "pt"})
    expect_error(copy, "image_encoder", "missing keys", "visual_projection.weight")


def test_wrong_shapes_in_the_weights(copy):
    file = copy / "unet" / "diffusion_pytorch_model.safetensors"
    weights = load_file(file)
    weights["conv_in.weight"] = weights["conv_in.weight"][:, :4].contiguous()
    save_file(weights, file)
    expect_error(copy, "unet", "conv_in.weight")


def test_wrong_shapes_in_the_projection(copy):
    file = copy / "cc_projection" / "diffusion_pytorch_model.safetensors"
    weights = load_file(file)
    weights["projection.weight"] = torch.zeros(32, 20)
    save_file(weights, file)
    expect_error(copy, "cc_projection", "does not match")


def test_parts_that_do_not_fit_together(copy):
    """A consistent 4-channel UNet (plain Stable Diffusion) is not Zero-1-to-3."""
    UNet2DConditionModel(**{**Zero123Config.tiny().unet, "in_channels": 4}).save_pretrained(copy / "unet")
    expect_error(copy, "in_channels 4 != 2 x vae latent_channels 4")


class Payload:
    """Unpickled, it would create ``marker``: proof that a refused pickle never ran."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return open, (str(self.marker), "w")


def text(name):
    def make(tmp_path, saved):
        (tmp_path / name).write_text("<html><body>404 Not Found</body></html>\n")
        return tmp_path / name
    return make


def write(name, content):
    def make(tmp_path, saved):
        (tmp_path / name).write_bytes(content(tmp_path, saved))
        return tmp_path / name
    return make


def saved_bytes(tmp_path, state, keep, **options):
    """The bytes of ``torch.save(state, **options)`` cut to the share ``keep`` of their length."""
    torch.save(state, tmp_path / "whole.ckpt", **options)
    data = (tmp_path / "whole.ckpt").read_bytes()
    return data[: int(len(data) * keep)]


def folder(damage):
    def make(tmp_path, saved):
        damage(shutil.copytree(saved, tmp_path / "model"))
        return tmp_path / "model"
    return make


def cut_in_half(file):
    file.write_bytes(file.read_bytes()[: file.stat().st_size // 2])


BROKEN_MODEL_PATHS = {
    "text file as .ckpt": (text("zero123.ckpt"), ["a text file, not a checkpoint", "404 Not Found"]),
    "text file as .safetensors": (text("zero123.safetensors"), ["a text file, not a checkpoint"]),
    "text file as .pth": (text("zero123.pth"), ["a text file, not a checkpoint"]),
    "Git LFS pointer": (write("105000.ckpt", lambda *_: b"version https://git-lfs.github.com/spec/v1\noid sha256:ab\n"),
                        ["a Git LFS pointer, not the weights", "git lfs pull"]),
    "random bytes": (write("zero123.ckpt", lambda *_: b"\x13" + random.Random(0).randbytes(4095)),
                     ["not a weight file: neither a PyTorch checkpoint (zip or pickle) nor safetensors"]),
    "empty file": (write("zero123.ckpt", lambda *_: b""), ["an empty file (0 bytes)"]),
    "truncated zip checkpoint": (
        write("zero123.ckpt", lambda tmp, _: saved_bytes(tmp, {"state_dict": {"w": torch.zeros(4096)}}, 0.5)),
        ["truncated or damaged: a zip archive", "interrupted download"]),
    "truncated legacy checkpoint": (
        write("zero123.ckpt", lambda tmp, _: saved_bytes(tmp, {"state_dict": {"w": torch.zeros(4096)}}, 0.5,
                                                         _use_new_zipfile_serialization=False)), ["truncated"]),
    "truncated safetensors": (
        write("zero123.safetensors", lambda tmp, saved: (saved / "vae" / "diffusion_pytorch_model.safetensors")
              .read_bytes()[:100_000]), ["truncated: its header lists"]),
    "zip that is not a checkpoint": (
        write("zero123.ckpt", lambda tmp, _: zipped({"readme.txt": "weights elsewhere"})),
        ["a zip archive but not a PyTorch checkpoint"]),
    "pickle with a payload": (
        write("zero123.ckpt", lambda tmp, _: pickle.dumps({"state_dict": Payload(tmp / "pwned")}, protocol=2)),
        ["unsafe pickle", "refused io.open"]),
    "zip checkpoint with a payload": (
        write("zero123.pth", lambda tmp, _: torch_saved({"state_dict": Payload(tmp / "pwned")}, tmp)),
        ["unsafe pickle", "refused io.open"]),
    "empty folder": (lambda tmp, _: tmp, ["missing part(s) unet, vae, image_encoder, cc_projection"]),
    "folder with one part missing": (folder(lambda root: shutil.rmtree(root / "image_encoder")),
                                     ["missing part(s) image_encoder"]),
    "folder with a truncated part": (
        folder(lambda root: cut_in_half(root / "unet" / "diffusion_pytorch_model.safetensors")),
        ["part 'unet'", "is truncated"]),
    "folder with a text file as a part's weights": (
        folder(lambda root: (root / "image_encoder" / "model.safetensors").write_text("oops")),
        ["part 'image_encoder'", "model.safetensors is a text file"]),
}


def zipped(entries):
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        for name, content in entries.items():
            archive.writestr(name, content)
    return buffer.getvalue()


def torch_saved(obj, tmp_path):
    torch.save(obj, tmp_path / "saved.pth")
    return (tmp_path / "saved.pth").read_bytes()


@pytest.mark.parametrize("case", sorted(BROKEN_MODEL_PATHS))
def test_every_broken_model_path_gives_one_error_naming_the_problem(case, saved, tmp_path):
    make, fragments = BROKEN_MODEL_PATHS[case]
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    expect_error(make(scratch, saved), *fragments)
    assert not (scratch / "pwned").exists(), "a refused pickle must never run"


def test_checkpoint_that_needs_code_execution(tmp_path):
    file = tmp_path / "zero123.ckpt"
    torch.save({"state_dict": {"cc_projection.weight": torch.zeros(2, 2)}, "hparams": argparse.Namespace(lr=1)}, file)
    expect_error(file, "unsafe pickle", "pickled Python objects", "refused argparse.Namespace")


def test_checkpoint_without_zero123_parts(tmp_path):
    file = tmp_path / "other.ckpt"
    torch.save({"state_dict": {"model.diffusion_model.conv_in.weight": torch.zeros(1)}, "global_step": 5}, file)
    expect_error(file, "not a Zero-1-to-3 checkpoint", "first_stage_model", "cc_projection")


def test_unknown_file_type_and_bad_precision(tmp_path):
    (tmp_path / "weights.txt").write_text("x")
    expect_error(tmp_path / "weights.txt", "unknown model file type")
    with pytest.raises(ValueError, match="precision"):
        load_predictor(str(tmp_path), precision="float8")
