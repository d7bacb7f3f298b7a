"""Build script of the accelcal_ros ament_python package."""
from glob import glob

from setuptools import find_packages, setup

package_name = 'accelcal_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    package_data={'accelcal_ros': ['py.typed']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', sorted(glob('config/*'))),
        ('share/' + package_name + '/launch', sorted(glob('launch/*.py'))),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='accelcal_ros developers',
    maintainer_email='dev@accelcal.invalid',
    description='ADXL345 field calibration, attitude, panorama, P2P and LiDAR boresight.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'imu_driver = accelcal_ros.nodes:imu_driver',
            'calibration = accelcal_ros.nodes:calibration',
            'attitude = accelcal_ros.nodes:attitude',
            'stitcher = accelcal_ros.nodes:stitcher',
            'p2p = accelcal_ros.nodes:p2p',
            'lidar_calibration = accelcal_ros.nodes:lidar_calibration',
            'rig_calibration = accelcal_ros.nodes:rig_calibration',
            'cloud_assembler = accelcal_ros.nodes:cloud_assembler',
            'calibration_frames = accelcal_ros.nodes:calibration_frames',
            'accelcal = accelcal_ros.cli:main',
        ],
    },
)
