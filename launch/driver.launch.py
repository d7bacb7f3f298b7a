"""Launch the ADXL345 driver with its parameter file (for real ROS 2 installs)."""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Start imu_driver with config/imu_driver.yaml; ``backend:=sim`` for the simulator."""
    params = os.path.join(get_package_share_directory('accelcal_ros'), 'config',
                          'imu_driver.yaml')
    return LaunchDescription([
        DeclareLaunchArgument('backend', default_value='i2c',
                              description='i2c, sim or replay'),
        Node(package='accelcal_ros', executable='imu_driver', name='imu_driver',
             parameters=[params, {'backend': LaunchConfiguration('backend')}],
             output='screen'),
    ])
