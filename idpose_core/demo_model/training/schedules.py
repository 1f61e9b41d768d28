"""What changes over the wall-time budget of a run: the share of robot crops and the learning rate."""
from __future__ import annotations

import math

from idpose_core.demo_model.training.options import TrainingOptions

WARM_UP = 0.02  # of the wall-time budget


def robot_share_at(progress: float, options: TrainingOptions) -> float:
    """The share of robot crops among the fresh pairs at ``progress`` (0..1) of the budget."""
    ramp = ((progress - options.robot_from) / options.robot_ramp if options.robot_ramp > 0
            else float(progress >= options.robot_from))
    return options.robot_share * min(1.0, max(0.0, ramp))


def learning_rate_factor(progress: float) -> float:
    """Linear warm-up over the first WARM_UP of the wall-time budget, then a cosine decay to a tenth."""
    cosine = 0.5 * (1.0 + math.cos(math.pi * min(1.0, progress)))
    return min(1.0, max(progress, 1e-3) / WARM_UP) * (0.1 + 0.9 * cosine)
