"""The command-line form of the evaluation options, shared by evaluate_bag, evaluate_dataset and the demo.

Each group is built from its option dataclass (``EstimatorOptions``, ``GroundTruthOptions`` with its
``ExtraTopics``, ``EvaluationProtocol``), whose defaults are the only definition; the parsers turn the
parsed arguments back into those dataclasses and name what is out of range.
"""
from __future__ import annotations

import argparse

from idpose_core.baselines import BASELINES
from idpose_core.devices import DEVICE_CHOICES
from idpose_core.evaluation.picks import PICK_SIZE
from idpose_core.evaluation.protocol import EvaluationProtocol
from idpose_core.gravity import rotation_from_extrinsic
from idpose_core.model_loading import PRECISIONS
from idpose_core.pipeline import DEPTH_POSES
from idpose_core.solver.config import PRESETS, VARIANTS
from idpose_ros.evaluation.bag_views import ExtraTopics
from idpose_ros.evaluation.estimators import MODES, EstimatorOptions
from idpose_ros.evaluation.ground_truth import GroundTruthOptions


def add_estimator_arguments(parser: argparse.ArgumentParser, preset: str = EstimatorOptions.preset) -> None:
    """The ``EstimatorOptions`` as command-line options (``preset`` is the default solver preset)."""
    default = EstimatorOptions()
    group = parser.add_argument_group("model and solver")
    group.add_argument("--mode", choices=MODES, default=default.mode,
                       help="offline: solver in this process; replay: through the estimator node over ROS")
    group.add_argument("--model-path", default=default.model_path,
                       help="Zero-1-to-3 diffusers folder or .ckpt (default: the embedded demo model)")
    group.add_argument("--device", choices=DEVICE_CHOICES, default=default.device)
    group.add_argument("--precision", choices=tuple(PRECISIONS), default=default.precision)
    group.add_argument("--preset", choices=tuple(PRESETS), default=preset, help=f"solver preset ({preset})")
    group.add_argument("--variant", choices=VARIANTS, default=default.variant, help="solver variant")
    group.add_argument("--solver-param", action="append", default=list(default.solver_params), metavar="NAME=VALUE",
                       help="override one of the node's solver parameters (repeatable)")
    group.add_argument("--image-size", type=int, default=default.image_size,
                       help=f"side of the preprocessed views the model sees (default {default.image_size})")
    group.add_argument("--depth-refinement", action=argparse.BooleanOptionalAction, default=default.depth_refinement,
                       help="set the poses of views with depth from their object points (default on)")
    group.add_argument("--depth-poses", choices=DEPTH_POSES, default=default.depth_poses,
                       help="with depth: verify (hypotheses from every source, one verifier) or refine (the "
                            f"diffusion estimate refined by registration); default {default.depth_poses}")
    group.add_argument("--node", default=default.node,
                       help="replay: fully qualified name of a running estimator node (default: start one)")
    group.add_argument("--timeout", type=float, default=default.timeout,
                       help=f"replay: seconds to wait for one estimate (default {default.timeout:g})")


def estimator_options(args: argparse.Namespace) -> EstimatorOptions:
    """The options ``add_estimator_arguments`` parsed."""
    return EstimatorOptions(mode=args.mode, model_path=args.model_path, device=args.device, precision=args.precision,
                            preset=args.preset, variant=args.variant, solver_params=tuple(args.solver_param),
                            image_size=args.image_size, depth_refinement=args.depth_refinement,
                            depth_poses=args.depth_poses, node=args.node,
                            timeout=args.timeout)


def add_ground_truth_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``GroundTruthOptions`` (and its ``ExtraTopics``) as command-line options."""
    gt, extras = GroundTruthOptions(), ExtraTopics()
    group = parser.add_argument_group("views and ground truth")
    group.add_argument("--image-topic", default=gt.image_topic, help="sensor_msgs/Image or CompressedImage")
    group.add_argument("--world-frame", default=gt.world_frame,
                       help=f"frame of the ground truth (default {gt.world_frame})")
    group.add_argument("--gt-topic", default=gt.gt_topic,
                       help="geometry_msgs/PoseStamped ground truth (camera optical frame in the world frame), "
                            "matched by stamp; default: /tf + /tf_static")
    group.add_argument("--gt-tolerance", type=float, default=gt.gt_tolerance,
                       help=f"stamp tolerance for --gt-topic (s, default {gt.gt_tolerance:g})")
    group.add_argument("--true-mask-topic", default=gt.true_mask_topic,
                       help="the target's true masks (mono8), when the bag has them: offline, the report gives each "
                            f"view's mask IoU against them (default {gt.true_mask_topic})")
    group.add_argument("--object-center", type=float, nargs=3, default=gt.object_center, metavar=("X", "Y", "Z"),
                       help="object centre in the world frame (default origin)")
    group.add_argument("--up", type=float, nargs=3, default=gt.up, metavar=("X", "Y", "Z"),
                       help="world up axis (default +z)")
    group = parser.add_argument_group("the views' other inputs (each matched to the image by stamp)")
    group.add_argument("--depth-topic", default=extras.depth_topic,
                       help="aligned depth Image (16UC1 mm or 32FC1 m): segments the object, gives its distance")
    group.add_argument("--camera-info-topic", default=extras.camera_info_topic,
                       help="CameraInfo of the colour camera, the nearest in time to each view (needed by depth; "
                            "default: the image topic's camera_info when the bag has it; without, the baselines "
                            "assume a 60 deg field of view)")
    group.add_argument("--mask-topic", default=extras.mask_topic, help="object masks (mono8) from a segmentation node")
    group.add_argument("--gravity-topic", default=extras.gravity_topic,
                       help="sensor_msgs/Imu, or the optical frame's orientation in a z-up frame "
                            "(PoseStamped or QuaternionStamped): each view's roll and elevation; a PoseStamped "
                            "(the arm's camera pose) also proposes the poses between views with depth")
    group.add_argument("--imu-to-optical", type=float, nargs="+", default=extras.imu_to_optical, metavar="V",
                       help="rotation from the Imu frame to the optical frame: a quaternion X Y Z W or ROLL PITCH YAW "
                            "in radians, as the node's imu_to_optical (default: from the bag's transforms)")
    group.add_argument("--input-tolerance", type=float, default=extras.tolerance,
                       help=f"stamp tolerance for these inputs (s, default {extras.tolerance:g})")
    group.add_argument("--imu-window", type=float, default=extras.imu_window,
                       help=f"seconds of Imu readings before an image averaged into its gravity "
                            f"(default {extras.imu_window:g})")


def ground_truth_options(args: argparse.Namespace) -> GroundTruthOptions:
    """The options ``add_ground_truth_arguments`` parsed; ValueError names a rotation that is not one."""
    if args.imu_to_optical is not None:
        try:
            rotation_from_extrinsic(args.imu_to_optical)
        except ValueError as err:
            raise ValueError(f"--imu-to-optical: {err}") from None
    extras = ExtraTopics(args.depth_topic, args.mask_topic, args.camera_info_topic, args.gravity_topic,
                         tuple(args.imu_to_optical) if args.imu_to_optical else None, args.input_tolerance,
                         args.imu_window)
    return GroundTruthOptions(args.image_topic, args.world_frame, args.gt_topic, args.gt_tolerance,
                              tuple(args.object_center), tuple(args.up), extras, args.true_mask_topic)


def add_protocol_arguments(parser: argparse.ArgumentParser, samples_help: str = "random picks of 8 views") -> None:
    """The ``EvaluationProtocol`` as command-line options."""
    default = EvaluationProtocol()
    parser.add_argument("--samples", type=int, default=default.samples, help=f"{samples_help} (default "
                                                                              f"{default.samples})")
    parser.add_argument("--seed", type=int, default=default.seed,
                        help="seed of the picks and of the random-pose baseline")
    parser.add_argument("--n", type=int, nargs="+", default=list(default.view_counts),
                        help=f"view counts (default {' '.join(map(str, default.view_counts))})")


def protocol_options(parser: argparse.ArgumentParser, args: argparse.Namespace) -> EvaluationProtocol:
    """The protocol ``add_protocol_arguments`` parsed; a usage error (exit 2) for values out of range."""
    if args.samples < 1:
        parser.error(f"--samples must be at least 1, got {args.samples}")
    if any(not 2 <= n <= PICK_SIZE for n in args.n):
        parser.error(f"--n takes view counts from 2 to {PICK_SIZE}, got {args.n}")
    return EvaluationProtocol(args.samples, args.seed, tuple(args.n))


def add_baseline_arguments(parser: argparse.ArgumentParser) -> None:
    """``--baselines``: the classical methods run on the same views as ID-Pose."""
    parser.add_argument("--baselines", nargs="+", choices=tuple(BASELINES), default=[], metavar="NAME",
                        help=f"classical baselines on the same views: {', '.join(BASELINES)}")

