"""scripts/train_demo_model.py end to end at toy size: renders, trains, resumes, writes the model folder."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from idpose_core.demo_model import DemoPredictor

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "train_demo_model.py"
TOY = ["--threads", "1", "--train-views", "3", "--heldout-views", "3", "--image-size", "32", "--batch", "2",
       "--block-out-channels", "8", "16", "--pool", "8", "--pool-refresh", "1", "--gap-pairs", "2",
       "--check-pairs", "2", "--gap-every", "2", "--minutes", "30"]


def train(work: Path, out: Path, steps: int, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), "--work-dir", str(work), "--out", str(out),
                           "--max-steps", str(steps), *TOY, *extra], capture_output=True, text=True, timeout=600)


def test_training_resumes_and_writes_a_loadable_model_with_its_records(tmp_path):
    work, out = tmp_path / "work", tmp_path / "model"
    first = train(work, out, 2)
    assert first.returncode == 0, first.stderr[-2000:]
    assert (work / "checkpoint.pt").is_file() and (work / "train_0.npz").is_file()
    second = train(work, out, 4)
    assert second.returncode == 0, second.stderr[-2000:]
    assert "resumed from" in second.stdout and "at step 2" in second.stdout
    training = json.loads((out / "training.json").read_text())
    assert training["steps"] == 4 and training["seed"] == 0
    assert [phase["from_step"] for phase in training["phases"]] == [0, 2]
    assert training["data"]["objects"] == ["duck", "teddy", "mug", "soccerball", "lego", "desk"]
    rows = (work / "curve.csv").read_text().splitlines()
    assert rows[0].startswith("step,minutes,loss,gap_t") and len(rows) == 3  # header + steps 2 and 4
    predictor = DemoPredictor.from_pretrained(out)
    assert predictor.model.config.block_out_channels == (8, 16)
    assert 0.0 < predictor.solver_defaults["probe_t"] < 1.0


def test_the_robot_phase_starts_from_given_weights_on_lit_augmented_crops(tmp_path):
    clean = tmp_path / "clean"
    assert train(tmp_path / "work_clean", clean, 2).returncode == 0
    out = tmp_path / "robot"
    robot = train(tmp_path / "work_robot", out, 3, "--init-from", str(clean), "--lamps", "1",
                  "--robot-minutes", "30")
    assert robot.returncode == 0, robot.stderr[-2000:]
    assert "robot phase" in robot.stderr
    lit = np.load(tmp_path / "work_robot" / "lamps_0_1.npz")["rgb"]
    plain = np.load(tmp_path / "work_robot" / "train_0.npz")["rgb"]
    assert lit.shape == (6, 3, 1, 32, 32, 3) and not np.array_equal(lit[:, :, 0], plain)  # other lights
    training = json.loads((out / "training.json").read_text())
    assert training["initial_weights"]["training"]["steps"] == 2
    crops = training["robot_crops"]
    assert crops["lamps_per_object"] == 1 and crops["reference"]["occluder"] > 0 == crops["target"]["occluder"]
    assert training["steps"] == 3
    assert DemoPredictor.from_pretrained(out).model.config.block_out_channels == (8, 16)
