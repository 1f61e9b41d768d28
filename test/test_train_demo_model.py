"""scripts/train_demo_model.py end to end at toy size: renders, trains, resumes, writes the model folder; and the
schedule and loss of its library, ``idpose_core.demo_model.training``."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from idpose_core.demo_model import DemoDiffusionModel, DemoModelConfig, DemoPredictor
from idpose_core.demo_model.training import TrainingOptions
from idpose_core.demo_model.training.loss import WRONG_POLAR, training_loss, wrong_poses
from idpose_core.demo_model.training.schedules import robot_share_at
from idpose_core.synthetic.scenes import demo_objects

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "train_demo_model.py"
TOY = ["--threads", "1", "--train-views", "3", "--heldout-views", "3", "--image-size", "32", "--batch", "2",
       "--block-out-channels", "8", "16", "--pool", "8", "--pool-refresh", "1", "--gap-pairs", "2",
       "--check-pairs", "2", "--gap-every", "2", "--minutes", "30", "--toys", "2", "--mesh-variants", "1",
       "--blobs", "2", "--catalogue-views", "3", "--catalogue-size", "64", "--heldout-objects", "1", "--lamps", "1"]


def train(work: Path, out: Path, steps: int, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), "--work-dir", str(work), "--out", str(out),
                           "--max-steps", str(steps), *TOY, *extra], capture_output=True, text=True, timeout=600)


@pytest.mark.slow
def test_training_resumes_and_writes_a_loadable_model_with_its_records(tmp_path):
    work, out = tmp_path / "work", tmp_path / "model"
    first = train(work, out, 2)
    assert first.returncode == 0, first.stderr[-2000:]
    assert (work / "checkpoint.pt").is_file() and (work / "catalogue_0.npz").is_file()
    second = train(work, out, 4)
    assert second.returncode == 0, second.stderr[-2000:]
    assert "resumed from" in second.stdout and "at step 2" in second.stdout
    training = json.loads((out / "training.json").read_text())
    assert training["steps"] == 4 and training["seed"] == 0 and not training["finished"]
    assert [phase["from_step"] for phase in training["phases"]] == [0, 2]
    objects = training["data"]["objects"]
    assert objects["demo"] == [spec.name for spec in demo_objects()]
    assert len(objects["catalogue"]) == 2 + 2 + 15 and objects["heldout"] == ["blob_800", "toy_heldout_0000"]
    assert not set(objects["heldout"]) & set(objects["catalogue"])
    rows = (work / "curve.csv").read_text().splitlines()
    assert rows[0].startswith("step,minutes,loss,novel_gap_t") and len(rows) == 3  # header + steps 2 and 4
    predictor = DemoPredictor.from_pretrained(out)
    assert predictor.model.config.block_out_channels == (8, 16)
    assert predictor.model.view_head is None  # relative poses only: nothing object-specific
    assert 0.0 < predictor.solver_defaults["probe_t"] < 1.0


@pytest.mark.slow
def test_a_fresh_work_dir_goes_on_from_a_model_folder(tmp_path):
    """Another machine, without the checkpoint: --init-from takes the weights, steps and minutes of the folder,
    and its curve goes on in the new model folder."""
    first_out = tmp_path / "first"
    assert train(tmp_path / "work_a", first_out, 2).returncode == 0
    out = tmp_path / "second"
    run = train(tmp_path / "work_b", out, 4, "--init-from", str(first_out))
    assert run.returncode == 0, run.stderr[-2000:]
    assert "initialised from" in run.stdout and "at step 2" in run.stdout
    training = json.loads((out / "training.json").read_text())
    assert training["steps"] == 4 and [phase["from_step"] for phase in training["phases"]] == [0, 2]
    rows = (out / "curve.csv").read_text().splitlines()
    assert rows[0].startswith("step,") and [row.split(",")[0] for row in rows[1:]] == ["2", "4"]
    assert (out / "curve.png").stat().st_size > 0


@pytest.mark.slow
def test_robot_crops_come_in_after_the_clean_start_and_are_recorded(tmp_path):
    """With no clean start the first steps already draw robot crops: lamps rendered per object, the share and the
    augmentation recorded; the held-out curve follows novel objects, their robot crops and the demo objects."""
    out = tmp_path / "model"
    run = train(tmp_path / "work", out, 3, "--robot-from", "0", "--robot-ramp", "0", "--robot-share", "1")
    assert run.returncode == 0, run.stderr[-2000:]
    lit = np.load(tmp_path / "work" / "lamps_0_1.npz")["rgb"]
    plain = np.load(tmp_path / "work" / "train_0.npz")["rgb"]
    assert lit.shape == (6, 3, 1, 32, 32, 3) and not np.array_equal(lit[:, :, 0], plain)  # other lights
    catalogue_lit = np.load(tmp_path / "work" / "catalogue_lamps_0.npz")["rgb"]
    assert catalogue_lit.shape == (19, 3, 1, 64, 64, 3)
    assert "robot=100%" in run.stderr
    training = json.loads((out / "training.json").read_text())
    crops = training["robot_crops"]
    assert crops["share"] == 1 and crops["from"] == 0 and crops["lamps_per_demo_object"] == 1
    assert crops["reference"]["occluder"] > 0 == crops["target"]["occluder"]
    header = (tmp_path / "work" / "curve.csv").read_text().splitlines()[0].split(",")
    assert {"novel_gap_t400", "novel_robot_gap_t400", "demo_gap_t400", "novel_robot_acc30"} <= set(header)


def test_the_robot_share_grows_after_the_clean_start():
    """0 during the clean start, then linear up to the chosen share, then held."""
    options = TrainingOptions(robot_share=0.6, robot_from=0.2, robot_ramp=0.4)
    shares = [robot_share_at(progress, options) for progress in (0.0, 0.2, 0.4, 0.6, 0.9)]
    assert shares == pytest.approx([0.0, 0.0, 0.3, 0.6, 0.6])


def test_wrong_poses_turn_the_azimuth_at_least_30_degrees():
    pose = torch.tensor([[0.2, 6.0, 0.0]]).repeat(500, 1)
    wrong = wrong_poses(pose, np.random.default_rng(0))
    turn = torch.remainder(wrong[:, 1] - pose[:, 1], 2 * np.pi)
    assert float(turn.min()) >= np.pi / 6 - 1e-5 and float(turn.max()) <= 11 * np.pi / 6 + 1e-5
    assert float((wrong[:, 0] - pose[:, 0]).abs().max()) <= WRONG_POLAR + 1e-6
    assert torch.equal(wrong[:, 2], pose[:, 2])


def test_the_ranking_loss_adds_a_hinge_on_the_wrong_pose_error():
    """With weight 0 the loss is the denoising MSE alone; with a weight it adds a non-negative hinge, and the
    gradient reaches the model through the wrong pose's prediction too."""
    torch.manual_seed(0)
    model = DemoDiffusionModel(DemoModelConfig(resolution=16, block_out_channels=(8, 16), norm_num_groups=4,
                                               embedding_dim=16, encoder_layers=1, encoder_heads=2,
                                               absolute_view_conditioning=False, reference_warp=True))
    reference, target = torch.rand(2, 3, 16, 16) * 2 - 1, torch.rand(2, 3, 16, 16) * 2 - 1
    pose = torch.tensor([[0.0, 0.5, 0.0], [0.1, 2.0, 0.0]])
    t = torch.tensor([500, 800])
    torch.manual_seed(1)
    plain, denoising = training_loss(model, reference, target, pose, pose, t, 0.0, 0.2)
    assert torch.equal(plain, denoising)
    torch.manual_seed(1)
    ranked, same = training_loss(model, reference, target, pose, pose, t, 1.0, 0.2)
    torch.testing.assert_close(same, denoising)
    torch.testing.assert_close(ranked - same, torch.tensor(0.2))  # the wrong pose is the true one: no gap at all
