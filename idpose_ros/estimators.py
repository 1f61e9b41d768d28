"""What estimates a view set for the evaluators: the node's pipeline in this process, or the node over ROS.

``EstimatorOptions`` is the one definition of the model and solver options that ``evaluate_bag``,
``evaluate_dataset`` and the demo share (``add_estimator_arguments`` puts them on a command line);
``make_estimator`` turns them into a ``ViewSetEstimator`` with the model loaded once.
"""
from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from idpose_core.evaluation import ViewSetEstimate
from idpose_core.model_loading import PRECISIONS, load_predictor
from idpose_core.pipeline import estimate_view_poses, result_details
from idpose_core.predictor import NoisePredictor
from idpose_core.solver import Progress, SolverConfig
from idpose_ros.bag_views import ViewMessages
from idpose_ros.parameters import SOLVER_PARAMETERS, parameter_table, pipeline_settings, solver_config
from idpose_ros.replay import ReplayEstimator
from idpose_ros.view_inputs import view_input

NODE_BOUNDS = {name: spec["bounds"] for name, _, spec in parameter_table()}
DEFAULT_IMAGE_SIZE = next(default for name, default, _ in parameter_table() if name == "image_size")
MODES = ("offline", "replay")


class ViewSetEstimator(Protocol):
    """Estimates the poses of n views (the first is the anchor) given the anchor's polar angle and distance
    (a view's gravity and the anchor's depth, when given, take precedence).

    ``values`` are the node parameters it runs on; ``description`` says what estimates (mode, model,
    node); ``close()`` releases what it holds (a node, a ROS context).
    """

    values: dict[str, Any]
    description: dict[str, Any]

    def __call__(self, views: Sequence[ViewMessages], anchor_polar_deg: float, object_distance: float,
                 progress: Progress | None = None) -> ViewSetEstimate: ...

    def close(self) -> None: ...


@dataclass(frozen=True)
class EstimatorOptions:
    """The model and solver options of an evaluation, as the command lines take them.

    ``solver_params`` are ``NAME=VALUE`` overrides of the node's solver parameters; ``node`` and
    ``timeout`` apply to ``mode="replay"`` (a running node's name, or None to start one here).
    """

    mode: str = "offline"
    model_path: str = ""
    device: str = "auto"
    precision: str = "auto"
    preset: str = "default"
    variant: str | None = None
    solver_params: tuple[str, ...] = ()
    image_size: int = DEFAULT_IMAGE_SIZE
    node: str | None = None
    timeout: float = 3600.0

    def node_values(self) -> dict[str, Any]:
        """The node's parameter values that shape an estimate: the solver's (the preset, the variant and
        the overrides) and ``image_size``; both modes run on exactly these. ValueError names a bad one."""
        config = SolverConfig.preset(self.preset)
        values = {name: getattr(config, name) for name in SOLVER_PARAMETERS}
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
        solver_config({**values, "anchor_polar_deg": 90.0}).validate()
        low, high = NODE_BOUNDS["image_size"]
        if not low <= self.image_size <= high:
            raise ValueError(f"--image-size must be in [{low}, {high}] pixels, got {self.image_size}")
        return {**values, "image_size": self.image_size}


def add_estimator_arguments(parser: argparse.ArgumentParser, preset: str = "default") -> None:
    """The ``EstimatorOptions`` as command-line options (``preset`` is the default solver preset)."""
    group = parser.add_argument_group("model and solver")
    group.add_argument("--mode", choices=MODES, default="offline",
                       help="offline: solver in this process; replay: through the estimator node over ROS")
    group.add_argument("--model-path", default="",
                       help="Zero-1-to-3 diffusers folder or .ckpt (default: the embedded demo model)")
    group.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto")
    group.add_argument("--precision", choices=tuple(PRECISIONS), default="auto")
    group.add_argument("--preset", choices=("default", "fast"), default=preset, help=f"solver preset ({preset})")
    group.add_argument("--variant", choices=("full", "tr", "naive"), default=None, help="solver variant")
    group.add_argument("--solver-param", action="append", default=[], metavar="NAME=VALUE",
                       help="override one of the node's solver parameters (repeatable)")
    group.add_argument("--image-size", type=int, default=DEFAULT_IMAGE_SIZE,
                       help=f"side of the preprocessed views the model sees (default {DEFAULT_IMAGE_SIZE})")
    group.add_argument("--node", default=None,
                       help="replay: fully qualified name of a running estimator node (default: start one)")
    group.add_argument("--timeout", type=float, default=3600.0, help="replay: seconds to wait for one estimate")


def estimator_options(args: argparse.Namespace) -> EstimatorOptions:
    """The options ``add_estimator_arguments`` parsed."""
    return EstimatorOptions(mode=args.mode, model_path=args.model_path, device=args.device, precision=args.precision,
                            preset=args.preset, variant=args.variant, solver_params=tuple(args.solver_param),
                            image_size=args.image_size, node=args.node, timeout=args.timeout)


class OfflineEstimator:
    """Runs the node's pipeline in this process on the same parameters the node would get."""

    def __init__(self, predictor: NoisePredictor, values: dict[str, Any], model: dict[str, Any] | None = None,
                 preset: str = "default"):
        self.predictor, self.values = predictor, values
        self.description = {"mode": "offline", "model": model or {"predictor": type(predictor).__name__},
                            "solver_preset": preset}

    def __call__(self, views: Sequence[ViewMessages], anchor_polar_deg: float, object_distance: float,
                 progress: Progress | None = None) -> ViewSetEstimate:
        inputs = [view_input(view.image, view.depth, view.mask, view.camera_info, view.gravity_up) for view in views]
        settings = pipeline_settings({**self.values, "anchor_polar_deg": anchor_polar_deg,
                                      "object_distance": object_distance})
        start = time.perf_counter()
        result = estimate_view_poses(self.predictor, inputs, settings, progress=progress)
        solved = result.solver_result
        return ViewSetEstimate(result.poses, np.asarray(solved.scores), np.asarray(solved.ambiguous),
                               time.perf_counter() - start, result_details(result))

    def close(self) -> None:
        """Nothing to release: the model goes with the object."""


def make_estimator(options: EstimatorOptions) -> ViewSetEstimator:
    """The offline estimator (model loaded here, once) or the replay client (model loaded by the node).

    Raises ValueError for bad options, ``ModelLoadError`` and ``ReplayError``.
    """
    values = options.node_values()
    model = {"model_path": options.model_path, "device": options.device, "precision": options.precision}
    if options.mode == "offline":
        return OfflineEstimator(load_predictor(options.model_path, options.device, options.precision), values,
                                model, options.preset)
    if options.mode == "replay":
        return ReplayEstimator(values, preset=options.preset, node_name=options.node, timeout=options.timeout,
                               **model)
    raise ValueError(f"mode must be one of {', '.join(MODES)}, got {options.mode!r}")

