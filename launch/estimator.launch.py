"""Start the idpose_estimator node.

    ros2 launch idpose_ros estimator.launch.py [params_file:=<yaml>] [image_topic:=<topic>] [model_path:=<weights>]

``image_topic`` remaps the node's ``image`` subscription and ``image/compressed`` to
``<image_topic>/compressed`` (image_transport's naming); a non-empty ``model_path`` overrides the
one in ``params_file`` (default: the installed config/estimator.yaml).
"""
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

from launch import LaunchContext, LaunchDescription

PACKAGE = "idpose_ros"


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
