"""
Launch the camera rig calibration: the driver and ``rig_calibration``.

    ros2 launch accelcal_ros rig_calibration.launch.py backend:=sim
    ros2 launch accelcal_ros rig_calibration.launch.py driver:=false   # a driver already runs

Then ``ros2 service call /rig_calibration/start std_srvs/srv/Trigger``, rest the rig with
the board in view in a dozen poses, and call ``/rig_calibration/finish``: the rig file is
written to ``~/.ros/accelcal/rig.yaml`` (``output_file``), the poses to
``~/.ros/accelcal/rig_capture/session_<UTC time>/``. Arguments (the same in every launch
file of this package): ``driver`` (start ``imu_driver``: true or false), ``backend``
(i2c, sim or replay), and one ``<node>_params`` parameter file per node (default the
installed ``config/<node>.yaml``); ``calibration_file`` sets the accelerometer
calibration the node applies. When the driver cannot start (no I2C bus with the default
backend), the launch stops with the reason.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, Shutdown
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Return the launch description: imu_driver (optional) and rig_calibration."""
    config = os.path.join(get_package_share_directory('accelcal_ros'), 'config')
    return LaunchDescription([
        DeclareLaunchArgument('driver', default_value='true',
                              description='start imu_driver (false: one already runs)'),
        DeclareLaunchArgument('backend', default_value='i2c',
                              description='imu_driver sample source: i2c, sim or replay'),
        DeclareLaunchArgument('imu_driver_params',
                              default_value=os.path.join(config, 'imu_driver.yaml'),
                              description='parameter file of imu_driver'),
        DeclareLaunchArgument('rig_calibration_params',
                              default_value=os.path.join(config, 'rig_calibration.yaml'),
                              description='parameter file of rig_calibration'),
        DeclareLaunchArgument('calibration_file', default_value='',
                              description='accelerometer calibration YAML (empty: none)'),
        Node(package='accelcal_ros', executable='imu_driver', name='imu_driver',
             parameters=[LaunchConfiguration('imu_driver_params'),
                         {'backend': LaunchConfiguration('backend')}],
             condition=IfCondition(LaunchConfiguration('driver')),
             on_exit=[Shutdown(reason='imu_driver exited (its FATAL line above says why, e.g. '
                               'no I2C bus): stopping the launch; use backend:=sim to try '
                               'without hardware, or driver:=false when a driver runs')],
             output='screen'),
        Node(package='accelcal_ros', executable='rig_calibration', name='rig_calibration',
             parameters=[LaunchConfiguration('rig_calibration_params'),
                         {'calibration_file': LaunchConfiguration('calibration_file')}],
             output='screen'),
    ])
