"""The estimator and the camera simulator together (the paper's scene, or your system's):
``ros2 launch switchobs_ros estimator_camera_sim.launch.py``.

Arguments: ``estimator_params`` and ``camera_sim_params`` (default: the package's
config/estimator.yaml and config/camera_sim.yaml; the two must describe the same system and
schedule), ``namespace``, ``log_level``. camera_sim waits for its subscribers
(``wait_for_subscribers: 1``) so the estimator and a recorder see the first sample.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description() -> LaunchDescription:
    share = FindPackageShare("switchobs_ros")
    ns = LaunchConfiguration("namespace")
    log = ["--ros-args", "--log-level", LaunchConfiguration("log_level")]
    return LaunchDescription([
        DeclareLaunchArgument("estimator_params",
                              default_value=PathJoinSubstitution([share, "config", "estimator.yaml"]),
                              description="The estimator's parameters"),
        DeclareLaunchArgument("camera_sim_params",
                              default_value=PathJoinSubstitution([share, "config", "camera_sim.yaml"]),
                              description="camera_sim's parameters (the same system and schedule)"),
        DeclareLaunchArgument("namespace", default_value="", description="Namespace of both nodes"),
        DeclareLaunchArgument("log_level", default_value="info", description="rcl log level"),
        Node(package="switchobs_ros", executable="estimator", name="estimator", namespace=ns,
             parameters=[LaunchConfiguration("estimator_params")], arguments=log, output="screen"),
        Node(package="switchobs_ros", executable="camera_sim", name="camera_sim", namespace=ns,
             parameters=[LaunchConfiguration("camera_sim_params"), {"wait_for_subscribers": 1}], arguments=log,
             output="screen"),
    ])
