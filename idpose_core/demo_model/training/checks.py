"""What the curve follows on held-out pairs: the true-vs-wrong-pose loss gap and a grid-search inversion check."""
from __future__ import annotations

import math

import numpy as np
import torch

from idpose_core.cameras import spherical_to_c2w
from idpose_core.demo_model.demo_predictor import DemoPredictor
from idpose_core.demo_model.grid_check import grid_search, pose_grid, rotation_errors
from idpose_core.demo_model.model import DemoDiffusionModel
from idpose_core.demo_model.training.data import TrainingData, fixed_pairs
from idpose_core.demo_model.training.options import TrainingOptions
from idpose_core.demo_model.training_data import PairBatch, RenderedViews, RobotCrops
from idpose_core.metrics import random_pose_errors

GAP_TIMESTEPS = (400, 550, 700, 850)  # inside the default training range
CHECK_AZIMUTHS = 12
CHECK_POLARS_DEG = (-45.0, 0.0, 45.0)
ACCURACIES_DEG = (15, 30)  # the inversion check's RotAcc thresholds
CURVE_SETS = ("novel", "novel_robot", "demo")
"""The held-out sets the curve follows: clean pairs of held-out objects, the same objects as a robot's crops, and
held-out cameras of the six demo objects."""


@torch.no_grad()
def loss_gaps(predictor: DemoPredictor, pairs: PairBatch, seed: int) -> dict[int, float]:
    """Relative loss gap (wrong - true) / true at each of GAP_TIMESTEPS, same noise for both poses."""
    rng = np.random.default_rng(seed)
    count = len(pairs.pose)
    wrong = pairs.pose.clone()
    wrong[:, 1] = torch.remainder(wrong[:, 1] + torch.as_tensor(rng.uniform(math.pi / 3, 5 * math.pi / 3, count),
                                                                dtype=torch.float32), 2 * math.pi)
    views = predictor.encode(torch.cat([pairs.reference, pairs.target]))
    ref, tgt = torch.arange(count), torch.arange(count) + count
    noise = torch.randn((count, *views.noise_shape), generator=torch.Generator().manual_seed(seed))
    gaps = {}
    for t in GAP_TIMESTEPS:
        steps = torch.full((count,), t, dtype=torch.long)
        true_loss = predictor.noise_error(views, ref, tgt, pairs.pose, steps, noise).mean()
        wrong_loss = predictor.noise_error(views, ref, tgt, wrong, steps, noise).mean()
        gaps[t] = float((wrong_loss - true_loss) / true_loss)
    return gaps


def probe_timestep(gaps: dict[str, dict[int, float]], t_min: int, t_max: int) -> int:
    """The timestep with the largest loss gap, summed over the held-out sets, among those the model was trained at
    (``t_min``..``t_max``: the solver probes there)."""
    trained = [t for t in GAP_TIMESTEPS if t_min <= t <= t_max]
    if not trained:
        raise ValueError(f"no loss-gap timestep {GAP_TIMESTEPS} lies in the training range [{t_min}, {t_max}]")
    return max(trained, key=lambda t: sum(by_t[t] for by_t in gaps.values()))


def inversion_check(predictor: DemoPredictor, pairs: PairBatch, views: RenderedViews, t: int) -> dict[str, float]:
    """Grid-search RotAcc at each of ACCURACIES_DEG on held-out pairs (exploration only, one noise sample: cheap
    and coarse)."""
    candidates = pose_grid(CHECK_AZIMUTHS, CHECK_POLARS_DEG)
    predicted = grid_search(predictor, pairs.reference, pairs.target, candidates, t, noise_samples=1)
    errors = rotation_errors(predicted, *true_cameras(pairs, views))
    return {f"acc{a}": float(np.mean(errors < a)) for a in ACCURACIES_DEG}


def true_cameras(pairs: PairBatch, views: RenderedViews) -> tuple[np.ndarray, np.ndarray]:
    """Absolute cameras (P, 3) of the pairs' references and targets."""
    return (views.cameras[pairs.object_index, pairs.reference_index],
            views.cameras[pairs.object_index, pairs.target_index])


def describe(checks: dict[str, dict[str, float]]) -> str:
    """Inversion checks per held-out set, as the log prints them."""
    return ", ".join(f"{name} RotAcc" + " ".join(f"@{a} {c[f'acc{a}']:.0%}" for a in ACCURACIES_DEG)
                     for name, c in checks.items())


class HeldOut:
    """The held-out pairs the curve follows, per set of CURVE_SETS: fixed pairs for the loss gap and for the
    inversion check."""

    def __init__(self, options: TrainingOptions, data: TrainingData, model: DemoDiffusionModel):
        seed, crops = options.seed, RobotCrops(data.novel_lit)
        self.views = {"novel": data.novel, "novel_robot": data.novel, "demo": data.demo_heldout}
        self.gap = {"novel": fixed_pairs(data.novel, options.gap_pairs, seed + 1, model),
                    "novel_robot": fixed_pairs(data.novel, options.gap_pairs, seed + 4, model, crops),
                    "demo": fixed_pairs(data.demo_heldout, options.gap_pairs, seed + 6, model)}
        self.check = {"novel": fixed_pairs(data.novel, options.check_pairs, seed + 2, model),
                      "novel_robot": fixed_pairs(data.novel, options.check_pairs, seed + 5, model, crops),
                      "demo": fixed_pairs(data.demo_heldout, options.check_pairs, seed + 7, model)}
        self.seed = seed + 3

    def gaps(self, predictor: DemoPredictor) -> dict[str, dict[int, float]]:
        """The loss gaps per held-out set and timestep (the same noise at every call)."""
        return {name: loss_gaps(predictor, pairs, self.seed) for name, pairs in self.gap.items()}

    def checks(self, predictor: DemoPredictor, t: int) -> dict[str, dict[str, float]]:
        """The inversion check per held-out set at timestep ``t``."""
        return {name: inversion_check(predictor, pairs, self.views[name], t) for name, pairs in self.check.items()}

    def random_baseline(self, seed: int) -> str:
        """RotAcc at each of ACCURACIES_DEG of random poses on the novel check pairs."""
        errors, _ = random_pose_errors(*map(spherical_to_c2w, true_cameras(self.check["novel"], self.views["novel"])),
                                       200, np.random.default_rng(seed))
        return "RotAcc" + ", ".join(f"@{a} {np.mean(errors < a):.0%}" for a in ACCURACIES_DEG)
