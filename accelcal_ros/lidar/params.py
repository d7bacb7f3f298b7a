"""
Parameters of the ``lidar_calibration`` and ``cloud_assembler`` nodes (pure specifications).

The still-capture defaults are those of :class:`~accelcal_ros.lidar.capture.CaptureSettings`
(one source): :data:`CAPTURE_FIELDS` names the settings field of each parameter, and
:func:`capture_settings` builds the settings from parameter values.
"""
from typing import Any, Dict, Optional

from accelcal_ros.frame_tree import (ANGLE_LIMIT_DEG, frame_id_reason, frame_name_params,
                                     OFFSET_LIMIT_M)
from accelcal_ros.lidar.capture import CaptureSettings
from accelcal_ros.outputs import default_output, output_path_problem, output_validator
from accelcal_ros.paramspec import ParamSpec
from accelcal_ros.session_interface import status_period_spec

_CAPTURE = CaptureSettings()

CAPTURE_FIELDS = {
    'auto_capture': 'auto',
    'min_static_s': 'min_static_s',
    'gyro_std_threshold_rad_s': 'gyro_std_threshold_rad_s',
    'accel_std_threshold_m_s2': 'accel_std_threshold_m_s2',
    'clouds_per_capture': 'clouds_per_capture',
}
"""Parameter name -> :class:`CaptureSettings` field (defaults come from the dataclass)."""


def _cloud_output_ok(value):
    return output_path_problem(value, ('.ply', '.pcd', '.laz', '.las')) if value else None


MAP_COORDINATE_LIMIT_M = 1.0e8
"""Largest map coordinate (m) of ``map_origin``: every projected CRS of the Earth lies
within +-4e7 m (Web Mercator's extent), heights far inside."""


def _frame_or_empty_ok(value):
    return frame_id_reason(value) if value else None


def _rpy_ok(value):
    return None if len(value) in (0, 3) else 'give 3 angles (roll pitch yaw, deg) or none'


def _origin_ok(value):
    return None if len(value) in (0, 3) else 'give easting northing height (m) or none'


def _crs_ok(value):
    if not value:
        return None
    from accelcal_ros.errors import InputError
    from accelcal_ros.lidar.geodesy import resolve_crs

    try:
        resolve_crs(value, 0.0, 0.0)
    except InputError as exc:
        return str(exc)
    return None


LIDAR_CALIBRATION_PARAMS = (
    ParamSpec('output_file', default_output('boresight.yaml'), 'boresight YAML written by '
              'finish; ~ is expanded', validator=output_validator(('.yaml', '.yml'))),
    ParamSpec('prior_rpy_deg', [], 'nominal mounting LiDAR -> IMU (roll pitch yaw, deg, '
              'REP-103 fixed axes); empty = find the floor without a prior',
              kind='double_array', validator=_rpy_ok, minimum=-ANGLE_LIMIT_DEG,
              maximum=ANGLE_LIMIT_DEG, unit='deg'),
    ParamSpec('calibration_file', '', 'accelerometer calibration applied to the IMU '
              '(empty = none)', read_only=True),
    ParamSpec('auto_capture', _CAPTURE.auto, 'capture a position each time the rig rests'),
    ParamSpec('min_static_s', _CAPTURE.min_static_s, 'stillness needed before a capture',
              minimum=0.1, maximum=60.0, unit='s'),
    ParamSpec('gyro_std_threshold_rad_s', _CAPTURE.gyro_std_threshold_rad_s, 'still when '
              'every gyro axis varies less', minimum=1e-5, maximum=1.0, unit='rad/s'),
    ParamSpec('accel_std_threshold_m_s2', _CAPTURE.accel_std_threshold_m_s2, 'still when '
              'every accelerometer axis (20 ms means) varies less', minimum=1e-4, maximum=5.0,
              unit='m/s^2'),
    ParamSpec('clouds_per_capture', _CAPTURE.clouds_per_capture, 'scans merged per position',
              minimum=1, maximum=100),
    ParamSpec('points_reliable', False, 'subscribe to points with reliable QoS (drivers that '
              'publish reliable, e.g. velodyne; large scans are then retransmitted instead of '
              'lost); default best effort (sensor data)', read_only=True),
    ParamSpec('queue_depth', 100, 'scans queued by the points subscription: the backlog a '
              'stalled process catches up on (keep it well above clouds_per_capture)',
              minimum=1, maximum=1000, read_only=True),
    ParamSpec('imu_queue_depth', 2000, 'IMU samples queued by the imu/data_raw subscription '
              '(2000 = 40 s at 50 Hz, 5 s at 400 Hz)', minimum=10, maximum=100000,
              read_only=True),
    ParamSpec('min_positions', 3, 'positions needed before finish solves', minimum=2,
              maximum=1000),
    ParamSpec('distance_threshold_m', 0.05, 'MSAC inlier distance', minimum=0.001,
              maximum=1.0, unit='m'),
    ParamSpec('max_tilt_deg', 15.0, 'floor normal within this of the expected up (prior)',
              minimum=0.5, maximum=60.0, unit='deg'),
    ParamSpec('max_range_m', 30.0, 'crop radius of the floor search', minimum=1.0,
              maximum=200.0, unit='m'),
    ParamSpec('weighting', 'equal', 'pair weights: equal (paper) or from the noise of each pair',
              choices=('noise', 'equal')),
    status_period_spec('lidar_calibration'),
    ParamSpec('lever_arm_m', [0.0, 0.0, 0.0], 'LiDAR origin in the IMU frame (published with '
              'the boresight on /tf_static at finish)', lengths=(3,), minimum=-OFFSET_LIMIT_M,
              maximum=OFFSET_LIMIT_M, unit='m'),
    *frame_name_params('imu_frame', 'lidar_frame'),
)
"""Every parameter of the ``lidar_calibration`` node (see config/lidar_calibration.yaml)."""

CLOUD_ASSEMBLER_PARAMS = (
    ParamSpec('boresight_file', '', 'boresight YAML (R or rpy_deg, LiDAR -> IMU); empty = '
              'use boresight_rpy_deg', read_only=True),
    ParamSpec('boresight_rpy_deg', [0.0, 0.0, 0.0], 'boresight LiDAR -> IMU (roll pitch '
              'yaw, deg, REP-103 fixed axes) when no file is given', lengths=(3,),
              minimum=-ANGLE_LIMIT_DEG, maximum=ANGLE_LIMIT_DEG, read_only=True, unit='deg'),
    ParamSpec('lever_arm_m', [0.0, 0.0, 0.0], 'LiDAR origin in the IMU frame', lengths=(3,),
              minimum=-OFFSET_LIMIT_M, maximum=OFFSET_LIMIT_M, read_only=True, unit='m'),
    ParamSpec('time_field', '', 'per-point time field (empty = time, t or timestamp)',
              read_only=True),
    ParamSpec('frame_id', '', 'frame of the output (empty = the odometry header frame)',
              validator=_frame_or_empty_ok),
    ParamSpec('output_file', '', 'cloud file written by save and at shutdown (.ply, .pcd; '
              '.laz or .las with map_crs; empty = none)',
              validator=_cloud_output_ok),
    ParamSpec('map_crs', '', 'projected CRS of the odometry (e.g. EPSG:32637 for UTM 37N); set: '
              'points are published in frame map = CRS - map_origin (float32-safe) and save '
              'writes .laz/.las with this CRS; empty = the odometry frame as it is',
              read_only=True, validator=_crs_ok),
    ParamSpec('map_origin', [], 'CRS coordinates (easting northing height) of the map frame '
              'origin; empty = the first pose rounded to 1 km (logged)', kind='double_array',
              validator=_origin_ok, minimum=-MAP_COORDINATE_LIMIT_M,
              maximum=MAP_COORDINATE_LIMIT_M, read_only=True, unit='m'),
    ParamSpec('save_voxel_m', 0.0, 'thin the saved cloud to one point per voxel of this size '
              '(0 = every point)', minimum=0.0, maximum=100.0, unit='m'),
    ParamSpec('max_wait_s', 3.0, 'how long a scan waits for odometry to cover it, counted '
              'from the arrival of the newest pose on the running clock of the node (a CPU stall '
              'does not count): late odometry is waited for while it still comes; DDS '
              'repairs of reliable odometry after a stall took up to 1 s',
              minimum=0.0, maximum=10.0, unit='s'),
    ParamSpec('max_pose_gap_s', 0.25, 'points between two odometry poses further apart '
              'than this are dropped and counted, never interpolated across the gap (lost '
              'odometry on a moving platform; 0 = no limit)', minimum=0.0, maximum=3600.0,
              unit='s'),
    ParamSpec('pose_buffer_s', 30.0, 'odometry kept for interpolation', minimum=1.0,
              maximum=3600.0, unit='s', read_only=True),
    ParamSpec('points_reliable', False, 'subscribe to points with reliable QoS (drivers that '
              'publish reliable; large scans are retransmitted instead of lost)',
              read_only=True),
    ParamSpec('queue_depth', 20, 'scans queued by the subscription and the publisher',
              minimum=1, maximum=1000, read_only=True),
    ParamSpec('max_points', 5000000, 'accumulated points kept for saving', minimum=1000,
              maximum=200000000, read_only=True),
)
"""Every parameter of the ``cloud_assembler`` node (see config/cloud_assembler.yaml)."""


def capture_settings(values: Dict[str, Any],
                     settings: Optional[CaptureSettings] = None) -> CaptureSettings:
    """Return ``settings`` (or new :class:`CaptureSettings`) updated from parameter ``values``."""
    settings = settings if settings is not None else CaptureSettings()
    for name, field_name in CAPTURE_FIELDS.items():
        if name in values:
            setattr(settings, field_name, values[name])
    return settings
