"""
Launch the LiDAR-IMU nodes of accelcal_ros (paper B).

``ros2 launch accelcal_ros lidar.launch.py`` starts ``lidar_calibration`` and
``cloud_assembler`` with the parameter files in ``config/``. Remap ``points``, ``imu/data_raw``
and ``odom`` to your driver's topics, e.g. ``points:=velodyne_points``.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Return the launch description of the two LiDAR nodes."""
    config = os.path.join(get_package_share_directory('accelcal_ros'), 'config')
    points = LaunchConfiguration('points')
    imu = LaunchConfiguration('imu')
    odom = LaunchConfiguration('odom')
    return LaunchDescription([
        DeclareLaunchArgument('points', default_value='points',
                              description='PointCloud2 topic of the scanner'),
        DeclareLaunchArgument('imu', default_value='imu/data_raw',
                              description='sensor_msgs/Imu topic of the IMU'),
        DeclareLaunchArgument('odom', default_value='odom',
                              description='nav_msgs/Odometry of the navigation solution'),
        Node(package='accelcal_ros', executable='lidar_calibration', name='lidar_calibration',
             parameters=[os.path.join(config, 'lidar_calibration.yaml')],
             remappings=[('points', points), ('imu/data_raw', imu)], output='screen'),
        Node(package='accelcal_ros', executable='cloud_assembler', name='cloud_assembler',
             parameters=[os.path.join(config, 'cloud_assembler.yaml')],
             remappings=[('points', points), ('odom', odom)], output='screen'),
    ])
