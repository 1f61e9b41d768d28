"""``estimate_poses``: the ID-Pose solver end to end (validate, encode, explore, select, refine, score)."""
from __future__ import annotations

import threading
import time
from collections.abc import Sequence

import numpy as np
import torch

from idpose_core.cancellation import checked_in_modules, raise_if_cancelled
from idpose_core.noise_predictor import NoisePredictor
from idpose_core.solver.config import SolverConfig
from idpose_core.solver.context import Progress, SampleCount, SolverContext
from idpose_core.solver.exploration import explore
from idpose_core.solver.refinement import refine
from idpose_core.solver.result import SolverResult
from idpose_core.solver.scoring import score
from idpose_core.solver.selection import select
from idpose_core.solver.starts import search_starts
from idpose_core.spherical import wrap_azimuth

PIXEL_TOLERANCE = 1e-3
# The stages an estimate reports progress for, in the order they run.
STAGES = ("exploration", "selection", "refinement", "runner-up", "scoring")


def estimate_fraction(stage: str, done: int, total: int) -> float:
    """How far an estimate is, 0..1, from its current stage's progress: each stage of ``STAGES`` counts equally
    (their costs depend on the settings), so the figure is monotonic but not proportional to time."""
    if stage not in STAGES:
        return 0.0
    within = done / total if total > 0 else 1.0
    return (STAGES.index(stage) + min(max(within, 0.0), 1.0)) / len(STAGES)


def validated_images(images: torch.Tensor | Sequence[torch.Tensor]) -> torch.Tensor:
    """Stack and check input views: (N, 3, H, W) float, N >= 2, equal sizes, finite, in [-1, 1]."""
    if not isinstance(images, torch.Tensor):
        shapes = [tuple(getattr(image, "shape", ())) for image in images]
        if len(set(shapes)) > 1:
            raise ValueError(f"all views must have the same size, got shapes {shapes}")
        if not shapes:
            raise ValueError("no views given: need at least 2")
        images = torch.stack([torch.as_tensor(image) for image in images])
    if images.ndim != 4 or images.shape[1] != 3:
        raise ValueError(f"images must be (N, 3, H, W), got shape {tuple(images.shape)}")
    if images.shape[0] < 2:
        raise ValueError(f"need at least 2 views (an anchor and one more), got {images.shape[0]}")
    if not torch.is_floating_point(images):
        raise ValueError(f"images must be floating point in [-1, 1], got dtype {images.dtype}")
    finite = torch.isfinite(images).flatten(1).all(dim=1)
    if not finite.all():
        raise ValueError(f"views {torch.nonzero(~finite).flatten().tolist()} contain NaN or infinite pixels")
    low, high = float(images.min()), float(images.max())
    if low < -1.0 - PIXEL_TOLERANCE or high > 1.0 + PIXEL_TOLERANCE:
        raise ValueError(f"pixels must lie in [-1, 1], got range [{low:.3g}, {high:.3g}]")
    return images


def estimate_poses(predictor: NoisePredictor, images: torch.Tensor | Sequence[torch.Tensor],
                   config: SolverConfig | None = None, progress: Progress | None = None,
                   cancel: threading.Event | None = None, known_polar: Sequence[float] | None = None,
                   samples: SampleCount | None = None) -> SolverResult:
    """Relative poses from view 0 (the anchor) to views 1..N-1 by inverting ``predictor``.

    ``images`` (N, 3, H, W) in [-1, 1] (or a sequence of (3, H, W)); ``progress(stage, done, total)``
    is called as samples are evaluated; setting ``cancel`` stops with ``Cancelled`` before the next
    predictor call, or inside one at its next torch module (``checked_in_modules``). ``known_polar``
    (N-1,) are relative polar angles (radians) known from gravity, NaN where unknown: those views search
    azimuth only (``config.known_polar`` says whether refinement may move them); a schedule made for
    gravity (``config.gravity_fallback``) runs its fallback preset when no view's polar angle is known, and
    the result's ``note`` says so. ``samples(evaluated, differentiated)`` follows the predictor samples of
    the estimate as they are spent. Bad input raises ``ValueError`` before the predictor is touched. Seeded
    by ``config.seed``: repeated runs on the CPU are identical.
    """
    config = config or SolverConfig()
    config.validate()
    images = validated_images(images)
    known = None
    if known_polar is not None:
        known = torch.as_tensor(np.asarray(known_polar, dtype=np.float64), dtype=torch.float32)
        if known.shape != (len(images) - 1,) or bool(torch.isinf(known).any()):
            raise ValueError(f"known_polar must hold {len(images) - 1} finite angles or NaN, got "
                             f"{np.asarray(known_polar).tolist()}")
    note = ""
    if config.gravity_fallback and (known is None or not bool(torch.isfinite(known).any())):
        note = (f"ran the {config.gravity_fallback!r} schedule: the one asked for needs gravity, and no view's "
                "elevation is known")
        config = config.fallback()
    seconds: dict[str, float] = {}

    raise_if_cancelled(cancel, "setup")
    context: SolverContext | None = None
    with checked_in_modules(cancel, lambda: f"a model call ({context.stage if context else 'encoding'})"):
        clock = time.perf_counter()
        views = predictor.encode(images)
        seconds["encode"] = time.perf_counter() - clock
        if len(views) != len(images):
            raise ValueError(f"predictor encoded {len(views)} views from {len(images)} images")
        context = SolverContext(predictor, views, config, progress, cancel, known, samples)

        def timed(stage: str, work):
            start = time.perf_counter()
            out = work()
            seconds[stage] = time.perf_counter() - start
            return out

        search = explore if config.search == "grid" else search_starts
        candidates = timed("exploration", lambda: search(context, len(images)))
        start = timed("selection", lambda: select(context, candidates))
        poses = timed("refinement", lambda: refine(context, start, config.variant, config.refine_steps_per_view))
        poses[:, 1] = wrap_azimuth(poses[:, 1])
        scores, runner_poses, runner_scores, ambiguous, confidence = timed(
            "scoring", lambda: score(context, poses, candidates))
        runner_poses[:, 1] = wrap_azimuth(runner_poses[:, 1])
    return SolverResult(
        rel_poses=poses.double().numpy(),
        scores=scores.double().numpy(),
        runner_up_poses=runner_poses.double().numpy(),
        runner_up_scores=runner_scores.double().numpy(),
        ambiguous=ambiguous.numpy(),
        confidence=confidence.double().numpy(),
        forward_samples=context.forward_samples,
        backward_samples=context.backward_samples,
        stage_samples={stage: tuple(counts) for stage, counts in context.stage_samples.items()},
        stage_seconds=seconds,
        note=note,
    )
