"""What estimates a view set for the evaluators: the node's pipeline in this process, or the node over ROS.

``EstimatorOptions`` is the one definition of the model and solver options that ``evaluate_bag``,
``evaluate_dataset`` and the demo share (``cli_options`` puts them on a command line);
``make_estimator`` turns them into a ``ViewSetEstimator`` with the model loaded once.
"""
from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from idpose_core.evaluation.estimator import ViewSetEstimate, ViewSetEstimator
from idpose_core.model_loading import load_predictor
from idpose_core.noise_predictor import NoisePredictor
from idpose_core.pipeline import LEVEL_POLAR_DEG, estimate_view_poses, result_details, view_crops
from idpose_core.solver import Progress
from idpose_core.view_input import ViewInput
from idpose_ros.evaluation.replay import ReplayEstimator
from idpose_ros.node.parameters import (
    NEXT_VIEW_PARAMETERS,
    SOLVER_PARAMETERS,
    parameter_table,
    pipeline_settings,
    preset_values,
    solver_config,
)

NODE_BOUNDS = {name: spec["bounds"] for name, _, spec in parameter_table()}
NODE_DEFAULTS = {name: default for name, default, _ in parameter_table()}
MODES = ("offline", "replay")


@dataclass(frozen=True)
class EstimatorOptions:
    """The model and solver options of an evaluation, as the command lines take them.

    ``solver_params`` are ``NAME=VALUE`` overrides of the node's solver parameters; ``node`` and
    ``timeout`` apply to ``mode="replay"`` (a running node's name, or None to start one here);
    ``depth_refinement`` False keeps the diffusion poses of views with depth, and ``depth_poses`` says how depth
    sets them (the node's parameters). Options that are node parameters default to the node's defaults;
    ``ReplayEstimator`` takes its options from here and has no defaults of its own.
    """

    mode: str = "offline"
    model_path: str = NODE_DEFAULTS["model_path"]
    device: str = NODE_DEFAULTS["device"]
    precision: str = NODE_DEFAULTS["precision"]
    preset: str = "default"
    variant: str | None = None
    solver_params: tuple[str, ...] = ()
    image_size: int = NODE_DEFAULTS["image_size"]
    depth_refinement: bool = NODE_DEFAULTS["depth_refinement"]
    depth_poses: str = NODE_DEFAULTS["depth_poses"]
    node: str | None = None
    timeout: float = 3600.0

    def node_values(self) -> dict[str, Any]:
        """The node's parameter values that shape an estimate: the solver's (the preset, the variant and
        the overrides), ``image_size``, the depth refinement's and the next view's (the node's defaults); both
        modes run on exactly these. ValueError names a bad one."""
        values = {"preset": self.preset, **preset_values(self.preset)}
        if self.variant is not None:
            values["variant"] = self.variant
        for item in self.solver_params:
            name, sep, text = item.partition("=")
            if not sep or name not in SOLVER_PARAMETERS:
                raise ValueError(f"--solver-param {item!r}: expected NAME=VALUE with NAME one of "
                                 f"{', '.join(SOLVER_PARAMETERS)}")
            kind = type(values[name])
            try:
                values[name] = kind(text)
            except ValueError:
                raise ValueError(f"--solver-param {item!r}: {name} takes a {kind.__name__}") from None
        solver_config({**values, "anchor_polar_deg": LEVEL_POLAR_DEG}).validate()
        low, high = NODE_BOUNDS["image_size"]
        if not low <= self.image_size <= high:
            raise ValueError(f"--image-size must be in [{low}, {high}] pixels, got {self.image_size}")
        return {**values, "image_size": self.image_size, "depth_refinement": self.depth_refinement,
                "depth_poses": self.depth_poses, "diffusion_trust": NODE_DEFAULTS["diffusion_trust"],
                "cloud_voxel_size": NODE_DEFAULTS["cloud_voxel_size"],
                **{name: NODE_DEFAULTS[name] for name in NEXT_VIEW_PARAMETERS}}


class OfflineEstimator:
    """Runs the node's pipeline in this process on the same parameters the node would get."""

    def __init__(self, predictor: NoisePredictor, values: dict[str, Any], model: dict[str, Any] | None = None,
                 preset: str = "default", solver_overrides: dict[str, Any] | None = None):
        """``solver_overrides``: ``SolverConfig`` settings beyond the node's parameters (benchmarks' schedules)."""
        self.predictor, self.values, self.solver_overrides = predictor, values, solver_overrides or {}
        self.description = {"mode": "offline", "model": model or {"predictor": type(predictor).__name__},
                            "solver_preset": preset}

    def __call__(self, views: Sequence[ViewInput], anchor_polar_deg: float, object_distance: float,
                 progress: Progress | None = None) -> ViewSetEstimate:
        settings = pipeline_settings({**self.values, "anchor_polar_deg": anchor_polar_deg,
                                      "object_distance": object_distance})
        if self.solver_overrides:
            settings = dataclasses.replace(settings, solver=settings.solver.updated(**self.solver_overrides))
        start = time.perf_counter()
        result = estimate_view_poses(self.predictor, views, settings, progress=progress)
        solved = result.solver_result
        return ViewSetEstimate(result.poses, np.asarray(solved.scores), np.asarray(solved.ambiguous),
                               time.perf_counter() - start, result_details(result), tuple(result.masks),
                               view_crops(result.preprocessed.images),
                               None if result.depth is None else result.depth.cloud)

    def close(self) -> None:
        """Nothing to release: the model goes with the object."""


def make_estimator(options: EstimatorOptions, predictor: NoisePredictor | None = None) -> ViewSetEstimator:
    """The offline estimator (model loaded here, once) or the replay client (model loaded by the node);
    ``predictor``, when given, is the model either runs instead of loading the one the options name.

    Raises ValueError for bad options, ``ModelLoadError`` and ``ReplayError``.
    """
    values = options.node_values()
    model = {"model_path": options.model_path, "device": options.device, "precision": options.precision}
    if options.mode == "offline":
        predictor = predictor or load_predictor(options.model_path, options.device, options.precision)
        return OfflineEstimator(predictor, values, model, options.preset)
    if options.mode == "replay":
        return ReplayEstimator(values, preset=options.preset, node_name=options.node, timeout=options.timeout,
                               predictor=predictor, **model)
    raise ValueError(f"mode must be one of {', '.join(MODES)}, got {options.mode!r}")

