"""Start the idpose_estimator node.

    ros2 launch idpose_ros estimator.launch.py [params_file:=<yaml>] [image_topic:=<topic>] [model_path:=<weights>]

``image_topic`` remaps the node's ``image`` subscription and ``image/compressed`` to
``<image_topic>/compressed`` (image_transport's naming); a non-empty ``model_path`` overrides the
one in ``params_file`` (default: the installed config/estimator.yaml).

The node gets the Fast DDS profile config/fastdds_large_images.xml (a 32 MB shared-memory segment,
UDP kept for other hosts), without which most raw HD frames are lost on the way (README, "The
estimator node"), unless FASTRTPS_DEFAULT_PROFILES_FILE is set already (a profile of your own, or
empty to keep Fast DDS's defaults) or another RMW than Fast DDS is chosen. Start the camera driver
with the same variable: the publisher's segment is the one that counts.
"""
import os

from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

from launch import LaunchContext, LaunchDescription

PACKAGE = "idpose_ros"
PROFILE_VARIABLE = "FASTRTPS_DEFAULT_PROFILES_FILE"  # read by Fast DDS 2.x, the RMW of ROS 2 Jazzy
LARGE_IMAGES_PROFILE = "fastdds_large_images.xml"


def transport_environment(context: LaunchContext) -> dict[str, str]:
    """The large-image profile for the node's process, where it is safe: Fast DDS, no profile chosen already."""
    if PROFILE_VARIABLE in os.environ or os.environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp") != "rmw_fastrtps_cpp":
        return {}
    return {PROFILE_VARIABLE: PathJoinSubstitution([FindPackageShare(PACKAGE), "config", LARGE_IMAGES_PROFILE])
            .perform(context)}


def estimator_node(context: LaunchContext) -> list[Node]:
    """The node, with model_path overridden only when the argument is non-empty."""
    image_topic = LaunchConfiguration("image_topic")
    model_path = LaunchConfiguration("model_path").perform(context)
    overrides = [{"model_path": ParameterValue(model_path, value_type=str)}] if model_path else []
    return [Node(
        package=PACKAGE,
        executable="estimator",
        name="idpose_estimator",
        output="screen",
        emulate_tty=True,
        parameters=[LaunchConfiguration("params_file"), *overrides],
        remappings=[("image", image_topic), ("image/compressed", [image_topic, "/compressed"])],
        additional_env=transport_environment(context),
    )]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription([
        DeclareLaunchArgument(
            "params_file", default_value=PathJoinSubstitution([FindPackageShare(PACKAGE), "config", "estimator.yaml"]),
            description="YAML file with the idpose_estimator parameters"),
        DeclareLaunchArgument(
            "image_topic", default_value="image",
            description="sensor_msgs/Image topic of the views (its /compressed sibling is subscribed too)"),
        DeclareLaunchArgument(
            "model_path", default_value="",
            description="Zero-1-to-3 weights (diffusers folder or .ckpt); empty = the params file's value"),
        OpaqueFunction(function=estimator_node),
    ])
