"""
Roll and pitch of a whole recording: the one offline path of the tilt filter (pure core).

Used by ``accelcal attitude`` and by the stitch/P2P commands that derive the attitude
from a bag's IMU (:func:`accelcal_ros.recording.streams.attitude_series`): the samples go
through :class:`~accelcal_ros.sensor.tilt_filter.AttitudeFilter` (adaptive averaging;
gyro-aided when angular velocity is given; odometry-aided with a platform acceleration
from :func:`~accelcal_ros.sensor.odometry_aid.accel_series_g`) or, with
``time_constant_s`` > 0, through the former fixed low-pass
(:class:`~accelcal_ros.sensor.tilt.TiltEstimator`).

Odometry files: CSV ``t,v,yaw_rate`` (s, m/s, rad/s), times increasing (a row going
back in time is refused with its line: "odometry running backwards in time"), speeds within
:data:`MAX_ODOMETRY_SPEED_M_S` and yaw rates within :data:`MAX_ODOMETRY_YAW_RATE_RAD_S`
(a corrupt value such as 1e308 is refused with its line). Odometry whose times do not
overlap the recording's is refused (:func:`estimate_series`): it would aid nothing.
"""
import math
from typing import List, Optional, Sequence, Tuple

from accelcal_ros.errors import FileFormatError, InputError
from accelcal_ros.sensor.model import SensorModel
from accelcal_ros.sensor.odometry_aid import accel_series_g
from accelcal_ros.sensor.tilt import TiltEstimate, TiltEstimator
from accelcal_ros.sensor.tilt_filter import AttitudeFilter, FilterSettings
import numpy as np
from numpy.typing import ArrayLike

STOPPED_M_S = 0.05
"""Odometry speed below which the platform counts as stopped (gyro bias learning)."""
MAX_ODOMETRY_SPEED_M_S = 100.0
"""Largest odometry speed read (m/s, 360 km/h: beyond any ground vehicle carrying this)."""
MAX_ODOMETRY_YAW_RATE_RAD_S = 10.0
"""Largest odometry yaw rate read (rad/s, 573 deg/s: beyond any vehicle's turn)."""


def read_odometry_csv(path: str) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``(t s, v m/s, yaw_rate rad/s)`` of an odometry CSV (see the module text)."""
    from accelcal_ros.schema import ODOMETRY_CSV
    from accelcal_ros.textformats import read_numeric_csv

    columns = read_numeric_csv(path, ODOMETRY_CSV.required, finite=True)
    t = columns['t']
    if t.size < 2:
        raise FileFormatError(path, 'odometry needs at least 2 rows (t,v,yaw_rate)', 2)
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        k = int(back[0]) + 1
        raise FileFormatError(path, f'odometry running backwards in time: t = {t[k]:.6f} s '
                              f'after {t[k - 1]:.6f} s (times must increase)', k + 2)
    for name, bound, unit in (('v', MAX_ODOMETRY_SPEED_M_S, 'm/s'),
                              ('yaw_rate', MAX_ODOMETRY_YAW_RATE_RAD_S, 'rad/s')):
        beyond = np.flatnonzero(np.abs(columns[name]) > bound)
        if beyond.size:
            k = int(beyond[0])
            raise FileFormatError(path, f'odometry {name} = {columns[name][k]:.6g} {unit} at '
                                  f't = {t[k]:.6f} s is beyond {bound:g} {unit}: not a vehicle '
                                  'odometry (a corrupt value?)', k + 2)
    return t, columns['v'], columns['yaw_rate']


def odometry_coverage(t_s: ArrayLike, odometry_t_s: ArrayLike) -> float:
    """Return the fraction (0..1) of the recording's samples within the odometry's time span."""
    t = np.asarray(t_s, dtype=float).reshape(-1)
    odo_t = np.asarray(odometry_t_s, dtype=float).reshape(-1)
    if not t.size or not odo_t.size:
        return 0.0
    inside = (t >= odo_t[0]) & (t <= odo_t[-1])
    return float(np.count_nonzero(inside)) / t.size


def estimate_series(t_s: ArrayLike, accel_g: ArrayLike, gyro_rad_s: Optional[ArrayLike] = None,
                    odometry: Optional[Tuple[ArrayLike, ArrayLike, ArrayLike]] = None,
                    lever_arm_m: Sequence[float] = (0.0, 0.0, 0.0),
                    sensor_model: Optional[SensorModel] = None, tilt_std_rad: float = 0.0,
                    noise_std_g: Optional[Sequence[float]] = None,
                    settings: Optional[FilterSettings] = None, time_constant_s: float = 0.0,
                    accel_threshold_g: float = 0.05) -> List[Optional[TiltEstimate]]:
    """
    Return one estimate (or None for an impossible sample) per sample of a recording.

    ``t_s`` (N,) s, ``accel_g`` (N, 3) raw g, ``gyro_rad_s`` (N, 3) or None, ``odometry``
    ``(t, v, yaw_rate)`` arrays or None, ``lever_arm_m`` the sensor's position from the
    platform's reference point (the odometry's, and the gyro path's: :mod:`.lever_arm`).
    ``noise_std_g`` None: the datasheet noise at the recording's median rate.
    """
    from accelcal_ros.sensor.datasheet import datasheet_noise_std_g

    t = np.asarray(t_s, dtype=float).reshape(-1)
    accel = np.asarray(accel_g, dtype=float).reshape(-1, 3)
    if accel.shape[0] != t.size:
        raise InputError(f'{t.size} times for {accel.shape[0]} accelerometer samples')
    if noise_std_g is None:
        steps = np.diff(t)
        steps = steps[steps > 0]
        rate = 1.0 / float(np.median(steps)) if steps.size else 100.0
        noise_std_g = tuple(datasheet_noise_std_g(rate).tolist())
    model = sensor_model or SensorModel.identity()
    times = t.tolist()
    rows = accel.tolist()
    if time_constant_s > 0:
        legacy = TiltEstimator(model, noise_std_g, tilt_std_rad, time_constant_s,
                               accel_threshold_g)
        return [legacy.update(ti, ai) for ti, ai in zip(times, rows)]
    filt = AttitudeFilter(model, noise_std_g, tilt_std_rad, accel_threshold_g,
                          settings=settings, lever_arm_m=lever_arm_m)
    rates: List[Optional[list]] = [None] * t.size
    if gyro_rad_s is not None:
        gyro = np.asarray(gyro_rad_s, dtype=float).reshape(-1, 3)
        if gyro.shape[0] != t.size:
            raise InputError(f'{t.size} times for {gyro.shape[0]} gyro samples')
        rates = list(gyro.tolist())
    platform: List[Optional[list]] = [None] * t.size
    moving: List[Optional[bool]] = [None] * t.size
    if odometry is not None:
        odo_t, odo_v, odo_r = (np.asarray(a, dtype=float).reshape(-1) for a in odometry)
        if t.size and odo_t.size and odometry_coverage(t, odo_t) == 0.0:
            raise InputError(f'the odometry (t {odo_t[0]:.6g} to {odo_t[-1]:.6g} s) does not '
                             f'overlap the recording (t {t[0]:.6g} to {t[-1]:.6g} s): it would '
                             'aid no sample; give the odometry of this recording (same time '
                             'base)')
        series = accel_series_g(t, odo_t, odo_v, odo_r, lever_arm_m)
        speed = np.interp(t, odo_t, np.abs(odo_v))
        platform = [None if math.isnan(row[0]) else row for row in series.tolist()]
        moving = [None if p is None else bool(s > STOPPED_M_S)
                  for p, s in zip(platform, speed.tolist())]
    return [filt.update(ti, ai, gi, pi, mi)
            for ti, ai, gi, pi, mi in zip(times, rows, rates, platform, moving)]
