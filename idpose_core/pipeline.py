"""Buffered views -> camera poses in the anchor frame: the one path the node, the bag evaluator and the demo share.

preprocess_views -> estimate_poses -> anchor_frame_poses. No ROS here.
"""
from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import torch

from idpose_core.cameras import anchor_frame_poses
from idpose_core.predictor import NoisePredictor
from idpose_core.preprocessing import PreprocessedViews, preprocess_views
from idpose_core.solver import SolverConfig, SolverResult, estimate_poses

MODEL_IMAGE_SIZE = 256  # Zero-1-to-3's input side in pixels


@dataclass(frozen=True)
class PipelineResult:
    """``poses`` (N, 4, 4): camera k in the anchor camera's optical frame (poses[0] = identity)."""

    poses: np.ndarray
    solver_result: SolverResult
    preprocessed: PreprocessedViews


def estimate_view_poses(
    predictor: NoisePredictor,
    rgbs: Sequence[np.ndarray],
    alphas: Sequence[np.ndarray | None],
    solver_config: SolverConfig,
    anchor_polar: float,
    object_distance: float,
    progress: Callable[[str, int, int], None] | None = None,
    cancel: threading.Event | None = None,
    image_size: int = MODEL_IMAGE_SIZE,
) -> PipelineResult:
    """Estimate the poses of N >= 2 views, the first one the anchor.

    ``rgbs`` N images (H_i, W_i, 3) uint8, ``alphas`` N masks (H_i, W_i) uint8 or None (then
    the mask is computed); ``anchor_polar`` (rad) is the anchor camera's polar angle around the
    object and ``object_distance`` its distance to the object centre, which sets the metric
    scale; ``image_size`` is the side of the preprocessed views the model sees. A predictor's
    ``solver_defaults`` (the demo model's noise levels) fill settings left at the paper's defaults. Raises
    ``PreprocessingError``, ``ValueError`` for fewer than 2 views, and the solver's ``Cancelled``
    when ``cancel`` is set.
    """
    if len(rgbs) < 2 or len(rgbs) != len(alphas):
        raise ValueError(f"need at least 2 views with one alpha entry each, got {len(rgbs)} images "
                         f"and {len(alphas)} alphas")
    preprocessed = preprocess_views(list(rgbs), list(alphas), size=image_size)
    solver_config = solver_config.with_recommended(getattr(predictor, "solver_defaults", {}))
    solved = estimate_poses(predictor, preprocessed.images, solver_config, progress=progress, cancel=cancel)
    poses = anchor_frame_poses(solved.rel_poses, anchor_polar, object_distance)
    return PipelineResult(poses=poses, solver_result=solved, preprocessed=preprocessed)


def views_mosaic(images: torch.Tensor) -> np.ndarray:
    """Preprocessed views (N, 3, S, S) in [-1, 1] -> one RGB image (S, N*S, 3) uint8, side by side."""
    if images.ndim != 4 or images.shape[1] != 3:
        raise ValueError(f"expected images (N, 3, S, S), got shape {tuple(images.shape)}")
    pixels = ((images.detach().float().cpu().clamp(-1, 1) + 1) * 127.5).round().to(torch.uint8)
    return np.ascontiguousarray(torch.cat(list(pixels), dim=2).permute(1, 2, 0).numpy())
