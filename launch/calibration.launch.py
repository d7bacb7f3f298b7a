"""Launch the calibration and attitude nodes with their parameter files (real ROS 2 installs)."""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Start calibration + attitude; ``calibration_file:=...`` loads a saved calibration."""
    share = get_package_share_directory('accelcal_ros')
    calibration_params = os.path.join(share, 'config', 'calibration.yaml')
    attitude_params = os.path.join(share, 'config', 'attitude.yaml')
    return LaunchDescription([
        DeclareLaunchArgument('calibration_file', default_value='',
                              description='calibration YAML for the attitude node'),
        DeclareLaunchArgument('output_file',
                              default_value=os.path.expanduser(
                                  '~/.ros/accelcal/calibration.yaml'),
                              description='where calibration/finish writes the calibration'),
        Node(package='accelcal_ros', executable='calibration', name='calibration',
             parameters=[calibration_params,
                         {'output_file': LaunchConfiguration('output_file')}],
             output='screen'),
        Node(package='accelcal_ros', executable='attitude', name='attitude',
             parameters=[attitude_params,
                         {'calibration_file': LaunchConfiguration('calibration_file')}],
             output='screen'),
    ])
