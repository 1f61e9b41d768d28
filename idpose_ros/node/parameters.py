"""The estimator's ROS parameters: one table with descriptions, ranges and choices, and their checks.

Solver parameters carry ``SolverConfig``'s field names and defaults, and the node's parameters that shape an
estimate take their defaults from ``PipelineSettings``, ``ReachableSet`` and ``VerificationSettings``, so the node
and the core cannot drift apart; ``SolverConfig.validate`` has the last word on combinations.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from idpose_core.devices import DEVICE_CHOICES
from idpose_core.gravity import IMU_WINDOW_S, rotation_from_extrinsic
from idpose_core.model_loading import PRECISIONS
from idpose_core.next_view import CRITERIA, ReachableSet
from idpose_core.pipeline import ANCHOR_POLAR_RANGE_DEG, DEPTH_POSES, LEVEL_POLAR_DEG, PipelineSettings
from idpose_core.pose_hypotheses import VerificationSettings
from idpose_core.solver import SolverConfig
from idpose_core.solver.config import KNOWN_POLAR_MODES, PRESETS, VARIANTS
from idpose_core.stamps import INPUT_TOLERANCE_S
from idpose_ros.node.input_sync import GravityMode
from idpose_ros.node.view_buffer import CaptureMode

INT32_MAX = 2**31 - 1


def _spec(description: str, *, choices: tuple[str, ...] = (), bounds: tuple[float, float] | None = None,
          read_only: bool = False) -> dict[str, Any]:
    return {"description": description, "choices": choices, "bounds": bounds, "read_only": read_only}


def _choices(kind: type[StrEnum]) -> tuple[str, ...]:
    """The values of an enum: the choices of the parameter that takes it."""
    return tuple(member.value for member in kind)


@dataclass(frozen=True)
class NodeSettings:
    """The node's own parameters (the solver's are in ``SOLVER_PARAMETERS``)."""

    model_path: str = field(default="", metadata=_spec(
        "Zero-1-to-3 weights: a diffusers folder or an LDM .ckpt; empty = the embedded default model "
        "(a folder scripts/train_demo_model.py wrote is a demo model too)",
        read_only=True))
    device: str = field(default="auto", metadata=_spec(
        "where the model runs (auto = cuda when available)", choices=DEVICE_CHOICES, read_only=True))
    precision: str = field(default="auto", metadata=_spec(
        "model dtype (auto = float32 on cpu, bfloat16 or float16 on cuda; bfloat16 on a cpu with avx512_bf16 "
        "or AMX is about twice as fast as float32)",
        choices=tuple(PRECISIONS), read_only=True))
    load_model_at_startup: bool = field(default=True, metadata=_spec(
        "load the model at the lifecycle configure transition (false: on the first estimate)", read_only=True))
    autostart: bool = field(default=True, metadata=_spec(
        "walk the lifecycle to active (configure, activate) when the node starts; false: wait for a lifecycle "
        "manager", read_only=True))
    capture_mode: CaptureMode = field(default=CaptureMode.AUTO, metadata=_spec(
        "auto: keep every image min_view_interval s after the last kept one; on_request: ~/capture keeps "
        "the latest image", choices=_choices(CaptureMode)))
    min_view_interval: float = field(default=1.0, metadata=_spec(
        "seconds between two views kept in auto capture mode", bounds=(0.0, 3600.0)))
    max_views: int = field(default=8, metadata=_spec(
        "most views buffered (the first is the anchor); lowering it keeps views already buffered",
        bounds=(2, 64)))
    views_per_estimate: int = field(default=0, metadata=_spec(
        "start an estimate automatically when this many views are buffered (0 = only on ~/estimate)",
        bounds=(0, 64)))
    max_image_pixels: int = field(default=4096 * 4096, metadata=_spec(
        "largest image accepted, in pixels (width x height), read from the header before decoding; larger "
        "images are refused", bounds=(32 * 32, 2**28)))
    anchor_polar_deg: float = field(default=LEVEL_POLAR_DEG, metadata=_spec(
        "polar angle of the anchor camera around the object (deg from world up +z; 90 = level), "
        "turns relative spherical poses into SE(3) and narrows the polar search", bounds=ANCHOR_POLAR_RANGE_DEG))
    object_distance: float = field(default=PipelineSettings.object_distance, metadata=_spec(
        "anchor camera to object centre (m): the metric scale of the published positions",
        bounds=(0.001, 1000.0)))
    image_size: int = field(default=PipelineSettings.image_size, metadata=_spec(
        "side in pixels of the preprocessed views the model sees (Zero-1-to-3: 256)", bounds=(16, 1024)))
    depth_refinement: bool = field(default=PipelineSettings.depth_refinement, metadata=_spec(
        "refine the poses of views with depth and intrinsics by registering their object points onto the "
        "anchor's (metric 6-DoF poses, gated per view), and publish the fused object on ~/object_cloud and "
        "~/object_pose"))
    depth_poses: str = field(default=PipelineSettings.depth_poses, metadata=_spec(
        "how depth sets the poses: verify (hypotheses from registration, gravity, the arm and the diffusion "
        "estimate, chosen by one verifier on the views' depth) or refine (the diffusion estimate refined by "
        "registration, within a trust region)", choices=DEPTH_POSES))
    diffusion_trust: float = field(default=VerificationSettings.diffusion_trust, metadata=_spec(
        "with depth_poses verify, the head start a pose near the diffusion answer gets before the verifier scores it, "
        "times the solver's confidence (0: the diffusion answer is one hypothesis among the others, as it should "
        "be with the embedded demo model on an object it never saw)", bounds=(0.0, 5.0)))
    cloud_voxel_size: float = field(default=PipelineSettings.cloud_voxel_size, metadata=_spec(
        "voxel (m) the published object cloud is thinned to", bounds=(0.0005, 0.5)))
    anchor_frame: str = field(default="", metadata=_spec(
        "frame_id of the published poses; empty = the anchor image's header.frame_id"))
    publish_tf: bool = field(default=True, metadata=_spec(
        "broadcast every estimate on TF: <anchor frame> -> <tf_prefix>view_<k> per view, at the anchor's stamp "
        "(needs tf2_ros or tf2_msgs; the log says when TF is off)", read_only=True))
    tf_prefix: str = field(default="idpose_", metadata=_spec(
        "prefix of the TF child frames of the estimated cameras"))
    diagnostics_period: float = field(default=1.0, metadata=_spec(
        "seconds between two /diagnostics messages", bounds=(0.05, 60.0), read_only=True))
    gravity: GravityMode = field(default=GravityMode.AUTO, metadata=_spec(
        "each view's roll and elevation from the imu or camera_orientation/camera_pose topics: off, auto (when "
        "they publish), required (a view without a gravity reading within input_tolerance is refused)",
        choices=_choices(GravityMode), read_only=True))
    imu_to_optical: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0, 1.0], metadata=_spec(
        "rotation from the imu topic's frame to the camera's optical frame: a quaternion x y z w, or roll pitch "
        "yaw in radians (a RealSense accel or imu topic: 0 0 0 1)", read_only=True))
    imu_window: float = field(default=IMU_WINDOW_S, metadata=_spec(
        "seconds of accelerometer readings before an image averaged into its gravity", bounds=(0.0, 5.0),
        read_only=True))
    input_tolerance: float = field(default=INPUT_TOLERANCE_S, metadata=_spec(
        "largest stamp difference (s) between an image and its depth, mask or gravity reading",
        bounds=(0.0, 1.0), read_only=True))
    record_dir: str = field(default="", metadata=_spec(
        "folder of the flight recording: every kept view with its inputs, every published result, ~/reset and "
        "cancel events appended to an mcap file, flushed message by message; empty = no recording",
        read_only=True))
    resume: bool = field(default=True, metadata=_spec(
        "with record_dir: at start, refill the buffer with the views the newest recording kept since its last "
        "~/reset (a recording that cannot be read is set aside as <name>.refused)", read_only=True))
    record_max_bytes: int = field(default=2_000_000_000, metadata=_spec(
        "size at which the recording rotates to a new file (which starts with the buffered views)",
        bounds=(1_000_000, 2**40), read_only=True))
    next_view_polar_deg: list[float] = field(default_factory=lambda: list(ReachableSet.polar_deg), metadata=_spec(
        "polar angles (deg from up, low high) the next suggested camera may take: what the arm reaches"))
    next_view_azimuth_deg: list[float] = field(default_factory=lambda: list(ReachableSet.azimuth_deg), metadata=_spec(
        "azimuths (deg from the anchor camera's, counter-clockwise seen from above, low high) the next suggested "
        "camera may take"))
    next_view_distance: list[float] = field(default_factory=lambda: list(ReachableSet.distance), metadata=_spec(
        "distances (m, low high) the next camera may stand from the object; it stands at the anchor's, clipped "
        "into them"))
    next_view_step_deg: float = field(default=ReachableSet.step_deg, metadata=_spec(
        "grid step (deg) of the candidate cameras the next view is chosen from", bounds=(1.0, 90.0)))
    next_view_criterion: str = field(default=PipelineSettings.next_view_criterion, metadata=_spec(
        "how the next view is chosen when a view is ambiguous: bridge (a camera that links the trusted views to "
        "the ambiguous one under one hypothesis only) or contrast (a camera much nearer one hypothesis); with "
        "nothing ambiguous, the camera farthest from every view", choices=tuple(CRITERIA)))
    preset: str = field(default="", metadata=_spec(
        "named solver settings: setting it sets the solver parameters below to the preset's values and takes the "
        "solver's other settings from it (live: for gravity, else fast; ifusion: iFusion's pose search); empty = the "
        "solver parameters as set",
        choices=("", *PRESETS)))

    def __post_init__(self) -> None:
        """Parameter values arrive as plain strings: the modes become their enums."""
        object.__setattr__(self, "capture_mode", CaptureMode(self.capture_mode))
        object.__setattr__(self, "gravity", GravityMode(self.gravity))


SOLVER_PARAMETERS: dict[str, dict[str, Any]] = {
    "variant": _spec("multi-view solver: full (triangular exploration and refinement), tr (triangular "
                     "refinement only) or naive (pairs independent)", choices=VARIANTS),
    "azimuth_candidates": _spec("azimuth candidates explored per view", bounds=(1, 360)),
    "probe_batch": _spec("noise samples per candidate probe", bounds=(1, 1024)),
    "adjust_steps": _spec("gradient steps on the better half of the candidates", bounds=(0, 10000)),
    "adjust_lr": _spec("learning rate of the candidate adjustment", bounds=(0.0, 1000.0)),
    "keep_top": _spec("candidates kept per view after exploration", bounds=(1, 360)),
    "refine_steps_per_view": _spec("refinement steps per non-anchor view", bounds=(0, 1000000)),
    "refine_lr": _spec("learning rate of the refinement", bounds=(0.0, 1000.0)),
    "average_last": _spec("the answer is the mean of this many last refinement iterates", bounds=(1, 1000000)),
    "runner_up_steps": _spec("refinement steps per view polishing the runner-up candidate (ambiguity check)",
                             bounds=(0, 1000000)),
    "max_batch": _spec("largest batch sent to the model at once (lower it when memory is short)",
                       bounds=(1, 4096)),
    "grad_batch": _spec("samples differentiated in one backward pass (activation memory grows with it: "
                        "about 0.45 GB per sample for full-size Zero-1-to-3 in float32)", bounds=(1, 4096)),
    "seed": _spec("random seed of the solver's noise", bounds=(0, INT32_MAX)),
    "known_polar": _spec("views whose polar angle gravity gives: search azimuth only and keep that angle (fixed) "
                         "or let refinement move it (start)", choices=KNOWN_POLAR_MODES),
}


def parameter_table() -> list[tuple[str, Any, dict[str, Any]]]:
    """(name, default, spec) of every parameter, node first, then solver."""
    solver_defaults = SolverConfig()
    node = [(f.name, f.default if f.default is not dataclasses.MISSING else f.default_factory(), dict(f.metadata))
            for f in dataclasses.fields(NodeSettings)]
    solver = [(name, getattr(solver_defaults, name), spec) for name, spec in SOLVER_PARAMETERS.items()]
    return node + solver


def descriptor(name: str, default: Any, spec: dict[str, Any]) -> ParameterDescriptor:
    """A ParameterDescriptor with the description, the choices, the range and read-only flag."""
    text = spec["description"]
    if spec["choices"]:
        text += f" (one of {', '.join(spec['choices'])})"
    result = ParameterDescriptor(name=name, description=text, read_only=spec["read_only"])
    if spec["bounds"] is not None:
        low, high = spec["bounds"]
        if isinstance(default, bool) or not isinstance(default, (int, float)):
            raise TypeError(f"parameter {name}: bounds need a numeric default, got {default!r}")
        if isinstance(default, int):
            result.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=1)]
        else:
            result.floating_point_range = [FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)]
    return result


def problem(values: dict[str, Any]) -> str | None:
    """Why this complete set of parameter values cannot be used, or None when it can."""
    for name, _, spec in parameter_table():
        if spec["choices"] and values[name] not in spec["choices"]:
            return f"{name} must be one of {', '.join(spec['choices'])}, got {values[name]!r}"
    try:
        rotation_from_extrinsic(values["imu_to_optical"])
    except ValueError as exc:
        return f"imu_to_optical: {exc}"
    if values["views_per_estimate"] > values["max_views"]:
        return (f"views_per_estimate ({values['views_per_estimate']}) cannot exceed max_views "
                f"({values['max_views']})")
    try:
        reachable_set(values)
    except (ValueError, TypeError) as exc:
        return f"next_view_*: {exc}"
    try:
        solver_config(values).validate()
    except ValueError as exc:
        return f"invalid solver parameters: {exc}"
    return None


def solver_config(values: dict[str, Any]) -> SolverConfig:
    """The SolverConfig these parameter values describe.

    Every exposed setting counts as chosen (a ROS parameter always has a value), so a model's
    recommendations fill only the settings the node does not expose and the ``preset`` does not give
    (the preset gives those it names). The anchor's known polar angle also narrows the solver's relative
    polar candidates.
    """
    exposed = {name: values[name] for name in SOLVER_PARAMETERS}
    if values.get("preset"):
        return SolverConfig(**{**PRESETS[values["preset"]], **exposed, "anchor_polar_deg": values["anchor_polar_deg"]})
    return SolverConfig(anchor_polar_deg=values["anchor_polar_deg"], **exposed)


NEXT_VIEW_PARAMETERS = ("next_view_polar_deg", "next_view_azimuth_deg", "next_view_distance", "next_view_step_deg",
                        "next_view_criterion")


def reachable_set(values: dict[str, Any]) -> ReachableSet:
    """Where the next camera may stand, from the ``next_view_*`` parameters. Raises ValueError naming the range at
    fault (a range is two numbers, low then high)."""
    ranges = {}
    for name in ("polar_deg", "azimuth_deg", "distance"):
        bounds = values[f"next_view_{name}"]
        if len(bounds) != 2:
            raise ValueError(f"next_view_{name} must be two numbers (low high), got {list(bounds)}")
        ranges[name] = (float(bounds[0]), float(bounds[1]))
    return ReachableSet(**ranges, step_deg=float(values["next_view_step_deg"]))


def pipeline_settings(values: dict[str, Any]) -> PipelineSettings:
    """What one estimate runs on, from the node's parameter values: solver, object distance, image size, depth
    refinement and where the next view may stand."""
    return PipelineSettings(solver_config(values), values["object_distance"], values["image_size"],
                            values["depth_refinement"], values["cloud_voxel_size"], reachable_set(values),
                            values["next_view_criterion"], values["depth_poses"],
                            VerificationSettings(diffusion_trust=values["diffusion_trust"]))


def node_settings(values: dict[str, Any]) -> NodeSettings:
    return NodeSettings(**{f.name: values[f.name] for f in dataclasses.fields(NodeSettings)})


def optical_from_imu(settings: NodeSettings) -> np.ndarray:
    """The ``imu_to_optical`` rotation (3, 3) (``rotation_from_extrinsic``: a quaternion or roll pitch yaw)."""
    return rotation_from_extrinsic(settings.imu_to_optical)


def current_values(node: Node) -> dict[str, Any]:
    """Every parameter's current value (its default while it is not declared yet)."""
    return {name: node.get_parameter(name).value if node.has_parameter(name) else default
            for name, default, _ in parameter_table()}


def declare_parameters(node: Node) -> None:
    """Declare every parameter with its descriptor; every later change goes through ``problem``. Setting
    ``preset`` to a name (at start-up too) sets the exposed solver parameters to its values, except those
    set in the same call.

    Raises rclpy's InvalidParameterValueException naming the problem when an override is invalid.
    """
    def check(changes: list[Parameter]) -> SetParametersResult:
        reason = problem({**current_values(node), **{p.name: p.value for p in changes}})
        return SetParametersResult(successful=reason is None, reason=reason or "")

    node.add_on_set_parameters_callback(check)
    for name, default, spec in parameter_table():
        node.declare_parameter(name, default, descriptor(name, default, spec))

    def apply_preset(changes: list[Parameter]) -> None:
        """The exposed solver parameters at the preset's values (so ``ros2 param get`` shows what runs)."""
        named = {change.name for change in changes}
        for change in changes:
            if change.name == "preset" and change.value:
                node.set_parameters([Parameter(name, value=value) for name, value in preset_values(change.value).items()
                                     if name not in named])

    node.add_post_set_parameters_callback(apply_preset)
    apply_preset([node.get_parameter("preset")])


def preset_values(name: str) -> dict[str, Any]:
    """The exposed solver parameters at preset ``name``'s values: what the ``preset`` parameter, a goal's preset
    and an evaluation's preset set. ValueError names an unknown preset."""
    config = SolverConfig.preset(name)
    return {field: getattr(config, field) for field in SOLVER_PARAMETERS}
