"""The shipped demo model: small safetensors with their records, and better than random poses (n = 2).

Skips, saying so, while the package carries no demo weights (``idpose_core/assets/demo_model``).
The accuracy check is reduced for CI: 12 pairs from cameras no training run used (render seed 4242),
exploration only (12 azimuths x 3 polar offsets, one noise sample, no gradient refinement); the
random baseline is scored on the same pairs with 200 random guesses each.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from idpose_core.demo_model import EMBEDDED_MODEL_DIR, DemoPredictor
from idpose_core.cameras import spherical_to_c2w
from idpose_core.demo_model.grid_check import grid_search, pose_grid, rotation_errors
from idpose_core.demo_model.model import WEIGHTS_FILE
from idpose_core.demo_model.training_data import make_pairs, random_pairs, render_views
from idpose_core.metrics import random_pose_errors
from idpose_core.synthetic.scenes import demo_objects

pytestmark = pytest.mark.skipif(not (EMBEDDED_MODEL_DIR / WEIGHTS_FILE).is_file(),
                                reason=f"no demo weights shipped in {EMBEDDED_MODEL_DIR}")
POLARS_DEG = (-45.0, 0.0, 45.0)
SEED = 4242


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
def test_shipped_model_beats_random_poses_on_held_out_views():
    torch.set_num_threads(2)
    predictor = DemoPredictor.embedded()
    views = render_views(demo_objects(), views_per_object=6, image_size=128, seed=SEED)
    rng = np.random.default_rng(SEED)
    pairs = make_pairs(views, *random_pairs(views, rng, 12), lambda images: images)
    cameras = (views.cameras[pairs.object_index, pairs.reference_index],
               views.cameras[pairs.object_index, pairs.target_index])
    t = int(round(predictor.solver_defaults["probe_t"] * predictor.num_train_timesteps))
    estimates = grid_search(predictor, pairs.reference, pairs.target, pose_grid(12, POLARS_DEG), t, noise_samples=1)
    model_acc = float(np.mean(rotation_errors(estimates, *cameras) < 30))
    random_acc = float(np.mean(random_pose_errors(*map(spherical_to_c2w, cameras), 200, rng)[0] < 30))
    assert model_acc >= random_acc + 0.25, (model_acc, random_acc)
