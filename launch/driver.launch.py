"""
Launch the ADXL345 driver with its parameter file, and the calibrations on ``/tf_static``.

    ros2 launch accelcal_ros driver.launch.py backend:=sim

Arguments (the same in every launch file of this package): ``backend`` (i2c, sim or
replay) and ``imu_driver_params`` (parameter file, default the installed
``config/imu_driver.yaml``). ``calibration_frames`` (``calibration_frames_params``, default
``config/calibration_frames.yaml``: only ``base_link`` -> ``imu_link`` until its
``rig_file``/``boresight_file`` are set) publishes the frame tree the driver's
``imu_link`` hangs in.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Return the launch description: ``imu_driver`` and ``calibration_frames``."""
    config = os.path.join(get_package_share_directory('accelcal_ros'), 'config')
    return LaunchDescription([
        DeclareLaunchArgument('backend', default_value='i2c',
                              description='imu_driver sample source: i2c, sim or replay'),
        DeclareLaunchArgument('imu_driver_params',
                              default_value=os.path.join(config, 'imu_driver.yaml'),
                              description='parameter file of imu_driver'),
        DeclareLaunchArgument('calibration_frames_params',
                              default_value=os.path.join(config, 'calibration_frames.yaml'),
                              description='parameter file of calibration_frames'),
        Node(package='accelcal_ros', executable='imu_driver', name='imu_driver',
             parameters=[LaunchConfiguration('imu_driver_params'),
                         {'backend': LaunchConfiguration('backend')}],
             on_exit=[Shutdown(reason='imu_driver exited (its FATAL line above says why, e.g. '
                               'no I2C bus): stopping the launch; use backend:=sim to try '
                               'without hardware, or driver:=false when a driver runs')],
             output='screen'),
        Node(package='accelcal_ros', executable='calibration_frames', name='calibration_frames',
             parameters=[LaunchConfiguration('calibration_frames_params')], output='screen'),
    ])
