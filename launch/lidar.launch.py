"""
Launch the LiDAR-IMU nodes of accelcal_ros (paper B).

    ros2 launch accelcal_ros lidar.launch.py points:=velodyne_points odom:=odometry/filtered

starts ``imu_driver`` (``driver:=false`` when the LiDAR rig has its own IMU, with a gyro,
or a driver already runs), ``lidar_calibration`` and ``cloud_assembler``. Remap
``points``, ``imu`` and ``odom`` to your drivers' topics. When the driver cannot start
(no I2C bus with the default backend), the launch stops with the reason. Arguments (the same in every
launch file of this package): ``driver`` (start ``imu_driver``: true or false),
``backend`` (i2c, sim or replay), and one ``<node>_params`` parameter file per node
(default the installed ``config/<node>.yaml``).
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, Shutdown
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Return the launch description: imu_driver (optional) and the two LiDAR nodes."""
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
        DeclareLaunchArgument('driver', default_value='true',
                              description='start imu_driver (false: the rig has its own IMU '
                              'or a driver already runs)'),
        DeclareLaunchArgument('backend', default_value='i2c',
                              description='imu_driver sample source: i2c, sim or replay'),
        DeclareLaunchArgument('imu_driver_params',
                              default_value=os.path.join(config, 'imu_driver.yaml'),
                              description='parameter file of imu_driver'),
        DeclareLaunchArgument('lidar_calibration_params',
                              default_value=os.path.join(config, 'lidar_calibration.yaml'),
                              description='parameter file of lidar_calibration'),
        DeclareLaunchArgument('cloud_assembler_params',
                              default_value=os.path.join(config, 'cloud_assembler.yaml'),
                              description='parameter file of cloud_assembler'),
        Node(package='accelcal_ros', executable='imu_driver', name='imu_driver',
             parameters=[LaunchConfiguration('imu_driver_params'),
                         {'backend': LaunchConfiguration('backend')}],
             remappings=[('imu/data_raw', imu)],
             condition=IfCondition(LaunchConfiguration('driver')),
             on_exit=[Shutdown(reason='imu_driver exited (its FATAL line above says why, e.g. '
                               'no I2C bus): stopping the launch; use backend:=sim to try '
                               'without hardware, or driver:=false when a driver runs')],
             output='screen'),
        Node(package='accelcal_ros', executable='lidar_calibration', name='lidar_calibration',
             parameters=[LaunchConfiguration('lidar_calibration_params')],
             remappings=[('points', points), ('imu/data_raw', imu)], output='screen'),
        Node(package='accelcal_ros', executable='cloud_assembler', name='cloud_assembler',
             parameters=[LaunchConfiguration('cloud_assembler_params')],
             remappings=[('points', points), ('odom', odom)], output='screen'),
    ])
