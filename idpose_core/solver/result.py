"""``SolverResult``: relative poses, their scores, runner-ups and what the solve cost."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class SolverResult:
    """Outcome of ``estimate_poses`` for N views (index 0 = anchor); arrays have one row per view 1..N-1.

    ``rel_poses`` (N-1, 3): (d_polar, d_azimuth in [0, 2pi), d_radius) from the anchor to view i.
    ``scores`` (N-1,): the final pose's pairwise error under the fixed probe noise (lower is better).
    ``runner_up_poses`` (N-1, 3) / ``runner_up_scores`` (N-1,): the best probed candidate far from the
    answer (NaN if none) and its error under the same noise; ``ambiguous`` (N-1,) flags views whose
    runner-up is nearly as good and ``confidence`` (N-1,) in [0, 1] says how much worse the runner-up is
    (rules in ``idpose_core.solver.scoring``). ``forward_samples`` counts
    predictor samples evaluated, ``backward_samples`` those differentiated, ``stage_samples`` both per
    stage (the exploration's differentiated samples are its batched adjust steps, every other stage's
    are steps of one sample); ``stage_seconds`` maps stage name -> wall time; ``note`` is empty, or says why
    another schedule ran than the one asked for.
    """

    rel_poses: np.ndarray
    scores: np.ndarray
    runner_up_poses: np.ndarray
    runner_up_scores: np.ndarray
    ambiguous: np.ndarray
    confidence: np.ndarray
    forward_samples: int
    backward_samples: int
    stage_samples: dict[str, tuple[int, int]] = field(default_factory=dict)
    stage_seconds: dict[str, float] = field(default_factory=dict)
    note: str = ""
