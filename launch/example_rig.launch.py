"""An example rig: two Prophesee cameras (metavision_driver) and a DAVIS (libcaer_driver), each on its
own clock, and evsync_node putting all three on the first camera's timeline.

    ros2 launch evsync_ros example_rig.launch.py serial_0:=... serial_1:=... davis_serial:=...

The drivers run as their own launch files start them (a node per camera, ``driver_node``, events on
``<camera>/events``, one EventPacket per millisecond: ``event_message_time_threshold`` 1e-3, their
default). evsync reads config/example_rig.yaml: the three event topics, and the DAVIS's IMU, frames
and camera_info (libcaer_driver stamps them on the camera's clock) as its companions. Give each
Prophesee's serial: with two cameras on the host, '' would open the same one twice. Restamped streams come out on
``<topic>/synced``, offsets on /evsync/offsets, states on /diagnostics."""

from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

DRIVERS = ('metavision_driver', 'libcaer_driver')
"""The camera drivers this example starts. Not dependencies of evsync_ros (a rig of one make needs
one of them): README, "Packages a rig needs"."""


def check_drivers() -> None:
    """RuntimeError naming the drivers not installed and how to install them."""
    missing = []
    for package in DRIVERS:
        try:
            get_package_share_directory(package)
        except PackageNotFoundError:
            missing.append(package)
    if missing:
        apt = ' '.join('ros-jazzy-' + p.replace('_', '-') for p in missing)
        raise RuntimeError(f'example_rig.launch.py starts {", ".join(DRIVERS)}; not installed: {", ".join(missing)} '
                           f'(sudo apt install {apt}; libcaer_driver 1.5.4 or later stamps IMU and frames right)')


def generate_launch_description() -> LaunchDescription:
    check_drivers()
    rig = PathJoinSubstitution([FindPackageShare('evsync_ros'), 'config', 'example_rig.yaml'])
    # a node per camera, named after it: its topics are /<name>/events (and the DAVIS's /<name>/imu,
    # /<name>/image_raw, /<name>/camera_info), as in the drivers' own launch files
    prophesee_0 = Node(package='metavision_driver', executable='driver_node', name='prophesee_0', output='screen',
                       parameters=[{'serial': LaunchConfiguration('serial_0'), 'frame_id': 'prophesee_0',
                                    'event_message_time_threshold': 1.0e-3}])
    prophesee_1 = Node(package='metavision_driver', executable='driver_node', name='prophesee_1', output='screen',
                       parameters=[{'serial': LaunchConfiguration('serial_1'), 'frame_id': 'prophesee_1',
                                    'event_message_time_threshold': 1.0e-3}])
    davis = Node(package='libcaer_driver', executable='driver_node', name='davis', output='screen',
                 parameters=[{'device_type': 'davis', 'serial': LaunchConfiguration('davis_serial'),
                              'camera_frame_id': 'davis', 'imu_frame_id': 'davis_imu',
                              'event_message_time_threshold': 1.0e-3}])
    evsync = Node(package='evsync_ros', executable='evsync_node', name='evsync', output='screen',
                  parameters=[LaunchConfiguration('params_file')])
    return LaunchDescription([
        DeclareLaunchArgument('serial_0', default_value='', description="first Prophesee's serial ('' = any)"),
        DeclareLaunchArgument('serial_1', default_value='', description="second Prophesee's serial"),
        DeclareLaunchArgument('davis_serial', default_value='', description="DAVIS's serial ('' = any)"),
        DeclareLaunchArgument('params_file', default_value=rig, description='evsync_node parameter file'),
        prophesee_0, prophesee_1, davis, evsync,
    ])
