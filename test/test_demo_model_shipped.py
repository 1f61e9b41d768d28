"""The shipped demo model: small safetensors with their records, and better than random poses on the shipped bags.

Skips, saying so, where the package carries no demo weights (``idpose_core/assets/demo_model``).
The accuracy check is ``evaluate_bag`` (offline, n = 2) on every shipped demo bag with reduced
iterations (the fast preset with 30 refinement steps per view), against the random-pose baseline
that ``evaluate_bag`` scores on the same pairs.
"""
from __future__ import annotations

import json

import pytest

from idpose_core.demo_model import EMBEDDED_MODEL_DIR, DemoPredictor
from idpose_core.demo_model.model import WEIGHTS_FILE
from idpose_ros.demo import demo_bags
from idpose_ros.evaluate_bag import main as evaluate_bag

pytestmark = pytest.mark.skipif(not (EMBEDDED_MODEL_DIR / WEIGHTS_FILE).is_file(),
                                reason=f"no demo weights shipped in {EMBEDDED_MODEL_DIR}")
REDUCED = ["--preset", "fast", "--solver-param", "refine_steps_per_view=30", "--solver-param", "runner_up_steps=0"]


def test_shipped_files_are_small_safetensors_with_records():
    assert (EMBEDDED_MODEL_DIR / WEIGHTS_FILE).stat().st_size <= 20 * 1024 * 1024
    training = json.loads((EMBEDDED_MODEL_DIR / "training.json").read_text())
    for key in ("seed", "steps", "wall_minutes", "data", "final_check"):
        assert key in training, key
    defaults = DemoPredictor.embedded().solver_defaults
    assert 0.0 < defaults["probe_t"] < 1.0
    low, high = defaults["refine_t_range"]
    assert 0.0 < low <= high < 1.0


@pytest.mark.slow
def test_shipped_model_beats_random_poses_on_the_shipped_bags(tmp_path):
    """Two picks per bag (12 pairs over the six demo objects)."""
    hits, pairs, random_hits = 0, 0, 0.0
    for bag in demo_bags():
        out = tmp_path / bag.name
        assert evaluate_bag([str(bag), "--out", str(out), "--n", "2", "--samples", "2", *REDUCED]) == 0
        report = json.loads((out / "report.json").read_text())
        hits += sum(pair["rot_err_deg"] < 30 for pair in report["pairs"])
        pairs += len(report["pairs"])
        random_hits += report["random_baseline"]["aggregates"]["all"]["rot_acc_30"] * len(report["pairs"])
    model_acc, random_acc = hits / pairs, random_hits / pairs
    assert pairs == 12
    assert model_acc >= random_acc + 0.25 and model_acc >= 3 * random_acc, (model_acc, random_acc)
