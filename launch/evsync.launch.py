"""Start evsync_node with a parameter file.

    ros2 launch evsync_ros evsync.launch.py params_file:=/path/to/rig.yaml

params_file defaults to the shipped config/evsync.yaml (every parameter with its default; its
topics are examples: give your rig's in your own file, under the node name ``evsync``)."""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description() -> LaunchDescription:
    shipped = PathJoinSubstitution([FindPackageShare('evsync_ros'), 'config', 'evsync.yaml'])
    return LaunchDescription([
        DeclareLaunchArgument('params_file', default_value=shipped,
                              description='evsync_node parameter file (node name: evsync)'),
        Node(package='evsync_ros', executable='evsync_node', name='evsync', output='screen',
             parameters=[LaunchConfiguration('params_file')]),
    ])
