"""
Launch the driver, the calibration node and the attitude node with their parameter files.

    ros2 launch accelcal_ros calibration.launch.py backend:=sim
    ros2 launch accelcal_ros calibration.launch.py driver:=false   # a driver already runs

Arguments (the same in every launch file of this package): ``driver`` (start
``imu_driver``: true or false), ``backend`` (i2c, sim or replay), and one
``<node>_params`` parameter file per node (default the installed ``config/<node>.yaml``);
``calibration_file`` and ``output_file`` set those parameters.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, Shutdown
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Return the launch description: imu_driver (optional), calibration and attitude."""
    config = os.path.join(get_package_share_directory('accelcal_ros'), 'config')
    return LaunchDescription([
        DeclareLaunchArgument('driver', default_value='true',
                              description='start imu_driver (false: one already runs)'),
        DeclareLaunchArgument('backend', default_value='i2c',
                              description='imu_driver sample source: i2c, sim or replay'),
        DeclareLaunchArgument('imu_driver_params',
                              default_value=os.path.join(config, 'imu_driver.yaml'),
                              description='parameter file of imu_driver'),
        DeclareLaunchArgument('calibration_params',
                              default_value=os.path.join(config, 'calibration.yaml'),
                              description='parameter file of calibration'),
        DeclareLaunchArgument('attitude_params',
                              default_value=os.path.join(config, 'attitude.yaml'),
                              description='parameter file of attitude'),
        DeclareLaunchArgument('calibration_file', default_value='',
                              description='calibration YAML for the attitude node'),
        DeclareLaunchArgument('output_file',
                              default_value=os.path.expanduser(
                                  '~/.ros/accelcal/calibration.yaml'),
                              description='where calibration/finish writes the calibration'),
        Node(package='accelcal_ros', executable='imu_driver', name='imu_driver',
             parameters=[LaunchConfiguration('imu_driver_params'),
                         {'backend': LaunchConfiguration('backend')}],
             condition=IfCondition(LaunchConfiguration('driver')),
             on_exit=[Shutdown(reason='imu_driver exited (its FATAL line above says why, e.g. '
                               'no I2C bus): stopping the launch; use backend:=sim to try '
                               'without hardware, or driver:=false when a driver runs')],
             output='screen'),
        Node(package='accelcal_ros', executable='calibration', name='calibration',
             parameters=[LaunchConfiguration('calibration_params'),
                         {'output_file': LaunchConfiguration('output_file')}],
             output='screen'),
        Node(package='accelcal_ros', executable='attitude', name='attitude',
             parameters=[LaunchConfiguration('attitude_params'),
                         {'calibration_file': LaunchConfiguration('calibration_file')}],
             output='screen'),
    ])
