"""Views -> camera poses in the anchor frame: the one path the node, the bag evaluator and the demo share.

preprocess_views -> estimate_poses -> anchor_frame_poses. No ROS here.
"""
from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from idpose_core.cameras import anchor_frame_poses
from idpose_core.predictor import NoisePredictor
from idpose_core.preprocessing import PreprocessedViews, preprocess_views
from idpose_core.solver import Progress, SolverConfig, SolverResult, estimate_poses

MODEL_IMAGE_SIZE = 256  # Zero-1-to-3's input side in pixels
LEVEL_POLAR_DEG = 90.0  # the anchor's polar angle when nothing tells it: a level camera


@dataclass(frozen=True)
class ViewInput:
    """One view as the pipeline takes it: ``rgb`` (H, W, 3) uint8 and, when the image has one, its
    ``alpha`` (H, W) uint8 (the object mask; otherwise the mask is computed)."""

    rgb: np.ndarray
    alpha: np.ndarray | None = None


@dataclass(frozen=True)
class PipelineSettings:
    """How to estimate: the solver's settings (``solver.anchor_polar_deg`` is the anchor camera's polar
    angle around the object, None = level), the anchor's ``object_distance`` (metres, the scale of the
    published positions) and ``image_size``, the side of the preprocessed views the model sees."""

    solver: SolverConfig
    object_distance: float = 1.0
    image_size: int = MODEL_IMAGE_SIZE

    @property
    def anchor_polar(self) -> float:
        """The anchor's polar angle in radians."""
        return float(np.radians(self.solver.anchor_polar_deg or LEVEL_POLAR_DEG))


@dataclass(frozen=True)
class PipelineResult:
    """``poses`` (N, 4, 4): camera k in the anchor camera's optical frame (poses[0] = identity)."""

    poses: np.ndarray
    solver_result: SolverResult
    preprocessed: PreprocessedViews


def estimate_view_poses(predictor: NoisePredictor, views: Sequence[ViewInput], settings: PipelineSettings,
                        progress: Progress | None = None, cancel: threading.Event | None = None) -> PipelineResult:
    """Estimate the poses of N >= 2 views, the first one the anchor.

    The predictor's ``solver_defaults`` (the demo model's noise levels) fill the solver settings the
    caller did not choose. Raises ``PreprocessingError``, ``ValueError`` for fewer than 2 views, and
    ``Cancelled`` when ``cancel`` is set (checked between views while preprocessing, then in the solver).
    """
    if len(views) < 2:
        raise ValueError(f"need at least 2 views, got {len(views)}")
    preprocessed = preprocess_views([view.rgb for view in views], [view.alpha for view in views],
                                    size=settings.image_size, cancel=cancel)
    solver_config = settings.solver.with_recommended(predictor.solver_defaults)
    solved = estimate_poses(predictor, preprocessed.images, solver_config, progress=progress, cancel=cancel)
    poses = anchor_frame_poses(solved.rel_poses, settings.anchor_polar, settings.object_distance)
    return PipelineResult(poses=poses, solver_result=solved, preprocessed=preprocessed)


def views_mosaic(images: torch.Tensor) -> np.ndarray:
    """Preprocessed views (N, 3, S, S) in [-1, 1] -> one RGB image (S, N*S, 3) uint8, side by side."""
    if images.ndim != 4 or images.shape[1] != 3:
        raise ValueError(f"expected images (N, 3, S, S), got shape {tuple(images.shape)}")
    pixels = ((images.detach().float().cpu().clamp(-1, 1) + 1) * 127.5).round().to(torch.uint8)
    return np.ascontiguousarray(torch.cat(list(pixels), dim=2).permute(1, 2, 0).numpy())
