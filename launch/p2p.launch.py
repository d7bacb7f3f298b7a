"""
Launch the IMU driver, the attitude estimator and the p2p node for a real camera.

    ros2 launch accelcal_ros p2p.launch.py camera:=/camera calibration_file:=/path/to.yaml

The camera driver must publish ``<camera>/image_raw`` and ``<camera>/camera_info``.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Return the launch description: imu_driver, attitude and p2p."""
    params = os.path.join(get_package_share_directory('accelcal_ros'), 'config', 'p2p.yaml')
    camera = LaunchConfiguration('camera')
    return LaunchDescription([
        DeclareLaunchArgument('camera', default_value='/camera',
                              description='namespace of the camera driver'),
        DeclareLaunchArgument('calibration_file', default_value='',
                              description='accelerometer calibration file for attitude'),
        DeclareLaunchArgument('params_file', default_value=params,
                              description='parameters of the p2p node'),
        Node(package='accelcal_ros', executable='imu_driver', name='imu_driver',
             parameters=[{'backend': 'i2c'}]),
        Node(package='accelcal_ros', executable='attitude', name='attitude',
             parameters=[{'calibration_file': LaunchConfiguration('calibration_file')}]),
        Node(package='accelcal_ros', executable='p2p', name='p2p',
             parameters=[LaunchConfiguration('params_file')],
             remappings=[('image', [camera, '/image_raw']),
                         ('camera_info', [camera, '/camera_info'])]),
    ])
