"""
Launch the ``stitcher`` node (levelled panorama) with its parameters file.

    ros2 launch accelcal_ros stitcher.launch.py rig_file:=/path/to/rig.yaml \
        params_file:=/path/to/stitcher.yaml

``rig_file`` defaults to the installed example rig (5 cameras, config/rig_example.yaml);
the camera topics default to ``<camera name>/image_raw`` and the attitude comes from the
``attitude`` node on ``attitude``.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Return the launch description: one ``stitcher`` node."""
    share = get_package_share_directory('accelcal_ros')
    return LaunchDescription([
        DeclareLaunchArgument(
            'params_file', default_value=os.path.join(share, 'config', 'stitcher.yaml'),
            description='ros2 parameters file of the stitcher'),
        DeclareLaunchArgument(
            'rig_file', default_value=os.path.join(share, 'config', 'rig_example.yaml'),
            description='rig YAML (cameras: name, width, height, K, D, R)'),
        Node(package='accelcal_ros', executable='stitcher', name='stitcher', output='screen',
             parameters=[LaunchConfiguration('params_file'),
                         {'rig_file': LaunchConfiguration('rig_file')}]),
    ])
