"""
Launch the IMU driver, the attitude estimator and the p2p node for a real camera.

    ros2 launch accelcal_ros p2p.launch.py camera:=/camera calibration_file:=/path/to.yaml

The camera driver must publish ``<camera>/image_raw`` and ``<camera>/camera_info``.
Arguments (the same in every launch file of this package): ``driver`` (start
``imu_driver``: true or false), ``backend`` (i2c, sim or replay), and one
``<node>_params`` parameter file per node (default the installed ``config/<node>.yaml``).
``dds_profile`` (default the installed ``config/fastdds_large_shm.xml``) is the Fast DDS
profile of the image node: frames larger than Fast DDS's default 0.5 MB shared-memory
segment otherwise go over UDP and are lost at camera rates; start the camera drivers with
the same ``FASTRTPS_DEFAULT_PROFILES_FILE``.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, Shutdown
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Return the launch description: imu_driver (optional), attitude and p2p."""
    config = os.path.join(get_package_share_directory('accelcal_ros'), 'config')
    camera = LaunchConfiguration('camera')
    return LaunchDescription([
        DeclareLaunchArgument('camera', default_value='/camera',
                              description='namespace of the camera driver'),
        DeclareLaunchArgument('driver', default_value='true',
                              description='start imu_driver (false: one already runs)'),
        DeclareLaunchArgument('backend', default_value='i2c',
                              description='imu_driver sample source: i2c, sim or replay'),
        DeclareLaunchArgument('imu_driver_params',
                              default_value=os.path.join(config, 'imu_driver.yaml'),
                              description='parameter file of imu_driver'),
        DeclareLaunchArgument('attitude_params',
                              default_value=os.path.join(config, 'attitude.yaml'),
                              description='parameter file of attitude'),
        DeclareLaunchArgument('p2p_params', default_value=os.path.join(config, 'p2p.yaml'),
                              description='parameter file of p2p'),
        DeclareLaunchArgument('dds_profile',
                              default_value=os.path.join(config, 'fastdds_large_shm.xml'),
                              description='Fast DDS profile of the image nodes (large '
                                          'shared-memory segment; camera drivers need it too)'),
        DeclareLaunchArgument('calibration_file', default_value='',
                              description='accelerometer calibration file for attitude'),
        Node(package='accelcal_ros', executable='imu_driver', name='imu_driver',
             parameters=[LaunchConfiguration('imu_driver_params'),
                         {'backend': LaunchConfiguration('backend')}],
             condition=IfCondition(LaunchConfiguration('driver')),
             on_exit=[Shutdown(reason='imu_driver exited (its FATAL line above says why, e.g. '
                               'no I2C bus): stopping the launch; use backend:=sim to try '
                               'without hardware, or driver:=false when a driver runs')],
             output='screen'),
        Node(package='accelcal_ros', executable='attitude', name='attitude',
             parameters=[LaunchConfiguration('attitude_params'),
                         {'calibration_file': LaunchConfiguration('calibration_file')}],
             output='screen'),
        Node(package='accelcal_ros', executable='p2p', name='p2p',
             parameters=[LaunchConfiguration('p2p_params')],
             remappings=[('image', [camera, '/image_raw']),
                         ('camera_info', [camera, '/camera_info'])],
             additional_env={'FASTRTPS_DEFAULT_PROFILES_FILE':
                             LaunchConfiguration('dds_profile')},
             output='screen'),
    ])
