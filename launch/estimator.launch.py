"""The estimator node with a params file: ``ros2 launch switchobs_ros estimator.launch.py``.

Arguments: ``params_file`` (default: the package's config/estimator.yaml; copy
config/robot_template.yaml for your robot), ``namespace`` (one estimator per robot:
``namespace:=robot1`` puts its topics under /robot1/estimator/...), ``use_sim_time`` (a replay
with /clock), ``log_level``.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description() -> LaunchDescription:
    params_file = LaunchConfiguration("params_file")
    return LaunchDescription([
        DeclareLaunchArgument(
            "params_file",
            default_value=PathJoinSubstitution([FindPackageShare("switchobs_ros"), "config", "estimator.yaml"]),
            description="The estimator's parameters (a copy of config/robot_template.yaml for your robot)"),
        DeclareLaunchArgument("namespace", default_value="", description="Namespace of this robot's estimator"),
        DeclareLaunchArgument("use_sim_time", default_value="false", description="Use /clock (a replay)"),
        DeclareLaunchArgument("log_level", default_value="info", description="rcl log level"),
        Node(
            package="switchobs_ros",
            executable="estimator",
            name="estimator",
            namespace=LaunchConfiguration("namespace"),
            parameters=[params_file, {"use_sim_time": LaunchConfiguration("use_sim_time")}],
            arguments=["--ros-args", "--log-level", LaunchConfiguration("log_level")],
            output="screen",
        ),
    ])
