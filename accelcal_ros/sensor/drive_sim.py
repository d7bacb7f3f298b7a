r"""
A simulated vehicle drive with an accelerometer, a gyro and odometry (pure core).

Used by ``accelcal study motion``, the tests of the tilt filter and the benchmark: the
truth is known at every sample.

**Drive** (:data:`DRIVE_SEGMENTS`): still 5 s, pull away at 0.15 g, turns at 0.1, 0.2
and 0.3 g lateral, braking at 0.3 g to a 5 s stop (during which the gyro bias drifts),
a pull-away at 0.2 g, a 0.3 g turn and a 0.3 g stop. Accelerations change with a 1 s
smooth-step (jerk-limited). Lateral acceleration ``a_lat = v r`` gives the yaw rate.
The road has a grade and a bank that vary along it (+-2 deg over 200 m, +-1.5 deg
over 120 m); the body rolls
3 deg/g outwards in turns and pitches 2 deg/g nose down when braking.

**Truth.** Attitude ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (REP-103); body angular velocity
from the Euler rates; the specific force at the sensor (lever arm ``lever_arm_m`` from
the vehicle's reference point, body frame) ``f = R^T (a_world + g z) / g + (dw/dt x p +
w x (w x p)) / g``, ``a_world = Rz(yaw) (a_lon, a_lat, 0)``. Road vibration (while moving):
a sum of sinusoids 8-25 Hz, ``vibration_g`` rms on z and a third of it on x and y, and
0.5 deg/s rms on the gyro.

**Sensors.** Accelerometer: the ADXL345 datasheet noise at ``rate_hz``, quantised to
3.9 mg (calibrated: identity model). Gyro (ITG-3205-like): scale error +-1 %, a bias of
about 0.5 deg/s per axis that drifts by ``bias_drift_deg_s`` over the stop, and, with
``gy85`` (default), as ``imu_driver`` publishes the GY-85's: the chip samples at 1 kHz
through its low-pass (first order at the DLPF bandwidth the driver sets below half its
poll rate, :func:`gy85_poll_s`: 20 Hz at 100 Hz, 188 Hz at 800 Hz), adds 0.38 deg/s
rms of noise per 100 Hz of bandwidth (square root), is quantised to 1/14.375 deg/s,
read once per poll, and interpolated at each sample's stamp
(:mod:`accelcal_ros.sensor.gyro_sampling`); without it, white noise of 0.38 deg/s rms
at 100 Hz per sample (scaling with the square root of the rate). Odometry: 50 Hz,
speed noise 0.02 m/s, yaw-rate noise 0.003 rad/s.
"""
from dataclasses import dataclass
import math
from typing import Sequence, Tuple

from accelcal_ros.errors import InputError
from accelcal_ros.sensor.datasheet import datasheet_noise_std_g, FULL_RES_G_PER_LSB
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
import numpy as np

DRIVE_SEGMENTS: Tuple[Tuple[str, float, float, float], ...] = (
    # (label, duration s, longitudinal g, lateral g); changes ramp over RAMP_S
    ('still', 5.0, 0.0, 0.0),
    ('pull away 0.15 g', 6.0, 0.15, 0.0),
    ('cruise', 3.0, 0.0, 0.0),
    ('turn 0.1 g', 6.0, 0.0, 0.1),
    ('cruise', 3.0, 0.0, 0.0),
    ('turn 0.2 g', 6.0, 0.0, -0.2),
    ('cruise', 3.0, 0.0, 0.0),
    ('turn 0.3 g', 8.0, 0.0, 0.3),
    ('cruise', 3.0, 0.0, 0.0),
    ('brake 0.3 g', 3.0, -0.3, 0.0),
    ('stop (bias drifts)', 5.0, 0.0, 0.0),
    ('pull away 0.2 g', 4.0, 0.2, 0.0),
    ('turn 0.3 g', 5.0, 0.0, -0.3),
    ('brake 0.3 g', 2.0 / 0.75, -0.3, 0.0),   # 0.2 g x 4 s = 0.3 g x 2.67 s: stops smoothly
    ('still', 4.0, 0.0, 0.0),
)
RAMP_S = 1.0
"""Time over which an acceleration changes (s)."""
GYRO_NOISE_100HZ_RAD_S = math.radians(0.38)
"""Gyro noise at 100 Hz (ITG-3205 datasheet: 0.38 deg/s rms)."""
ODOMETRY_RATE_HZ = 50.0
VIBRATION_G = 0.03
"""The road's vibration by default (g rms on z, a third on x and y; 0: a smooth floor)."""


@dataclass
class Drive:
    """One simulated drive: truth and sensor streams (SI, rad; accelerometer in g)."""

    t: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    accel_g: np.ndarray
    gyro_rad_s: np.ndarray
    odo_t: np.ndarray
    odo_speed: np.ndarray
    odo_yaw_rate: np.ndarray
    segment: np.ndarray
    """Index into :data:`DRIVE_SEGMENTS` per sample."""
    lever_arm_m: Tuple[float, float, float]
    rate_hz: float


def _smooth_profile(t: np.ndarray, column: int) -> np.ndarray:
    """Return the commanded acceleration (g) of a segment column, ramped by smooth-steps."""
    out = np.zeros_like(t)
    start, previous = 0.0, 0.0
    for seg in DRIVE_SEGMENTS:
        value = float(seg[column])
        w = np.clip((t - start) / RAMP_S, 0.0, 1.0)
        step = w * w * (3.0 - 2.0 * w)
        out += np.where(t >= start, (value - previous) * step, 0.0)
        previous = value
        start += seg[1]
    return out


def _euler_rates_to_body(roll, pitch, d_roll, d_pitch, d_yaw):
    """Body angular velocity (N, 3) from ZYX Euler angles and their rates."""
    sr, cr = np.sin(roll), np.cos(roll)
    sp, cp = np.sin(pitch), np.cos(pitch)
    return np.stack([d_roll - d_yaw * sp, d_pitch * cr + d_yaw * sr * cp,
                     -d_pitch * sr + d_yaw * cr * cp], axis=1)


def _rotation(roll, pitch, yaw):
    """Rotation matrices (N, 3, 3) body -> world, Rz(yaw) Ry(pitch) Rx(roll)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler('ZYX', np.stack([yaw, pitch, roll], axis=1)).as_matrix()


def gy85_poll_s(rate_hz: float) -> float:
    """
    Return how often ``imu_driver`` polls the ADXL345 (and so reads the ITG-3205; s).

    The driver drains the FIFO every two samples, every 2.5 to 20 ms
    (:func:`accelcal_ros.driver.bus_timing.fifo_poll_period_s`, the same figures).
    """
    return min(max(2.0 / rate_hz, 0.0025), 0.02)


def _gy85_gyro(t: np.ndarray, signal: np.ndarray, rate_hz: float,
               rng: np.random.Generator, noise_scale: float) -> np.ndarray:
    """Return the gyro as ``imu_driver`` publishes it (see :func:`simulate_drive`)."""
    from accelcal_ros.sensor.gyro_sampling import (DLPF_BANDWIDTHS_HZ, DLPF_DELAY_S,
                                                   dlpf_for_rate, rates_at)
    from scipy.signal import lfilter

    poll = gy85_poll_s(rate_hz)
    code = dlpf_for_rate(min(1000.0, 1.0 / poll))
    bandwidth = DLPF_BANDWIDTHS_HZ[code]
    chip_t = np.arange(0.0, t[-1] + poll, 1e-3)   # the chip samples at 1 kHz
    fine = np.stack([np.interp(chip_t, t, signal[:, k]) for k in range(3)], axis=1)
    a = 1.0 - math.exp(-2 * math.pi * bandwidth * 1e-3)   # its low-pass, first order
    fine = lfilter([a], [1.0, a - 1.0], fine, axis=0, zi=(1.0 - a) * fine[:1])[0]
    reads_t = np.arange(poll, t[-1] + 2 * poll, poll)
    newest = np.floor(reads_t * 1000.0 + 1e-9).astype(int)
    reads = fine[np.minimum(newest, chip_t.size - 1)] + rng.standard_normal(
        (reads_t.size, 3)) * GYRO_NOISE_100HZ_RAD_S * math.sqrt(bandwidth / 100.0) * noise_scale
    lsb = math.radians(1.0 / 14.375)
    reads = np.round(reads / lsb) * lsb
    stamped = [(float(r - DLPF_DELAY_S[code]), *row) for r, row in
               zip(reads_t.tolist(), reads.tolist())]
    out = np.empty_like(signal)
    poll_of = np.searchsorted(reads_t, t - 1e-9)   # each sample goes out with the next read
    for k in np.unique(poll_of).tolist():
        rows = np.flatnonzero(poll_of == k)
        out[rows] = rates_at(stamped[max(0, k - 1):k + 1], t[rows].tolist(),
                             DLPF_DELAY_S[code], 1e-3)
    return out


def simulate_drive(rate_hz: float = 100.0, seed: int = 0,
                   lever_arm_m: Sequence[float] = (1.0, 0.3, 0.8),
                   vibration_g: float = VIBRATION_G, bias_drift_deg_s: float = 0.2,
                   noise_scale: float = 1.0, gy85: bool = True) -> Drive:
    """Return a :class:`Drive` sampled at ``rate_hz`` (see the module docstring)."""
    if not (rate_hz > 0 and vibration_g >= 0 and noise_scale >= 0):
        raise InputError('rate_hz must be positive, vibration_g and noise_scale >= 0')
    rng = np.random.default_rng(seed)
    g = STANDARD_GRAVITY_M_S2
    duration = sum(seg[1] for seg in DRIVE_SEGMENTS)
    t = np.arange(0.0, duration, 1.0 / rate_hz)
    dt = 1.0 / rate_hz
    a_lon = _smooth_profile(t, 2) * g
    a_lat_cmd = _smooth_profile(t, 3) * g
    speed = np.empty_like(t)
    v = 0.0
    for k, a in enumerate((a_lon * dt).tolist()):   # the vehicle stops; it never reverses
        v = max(v + a, 0.0)
        speed[k] = v
    yaw_rate = np.where(speed > 1.0, a_lat_cmd / np.maximum(speed, 1.0), 0.0)
    a_lat = speed * yaw_rate
    a_lon = np.gradient(speed, dt)
    yaw = np.cumsum(yaw_rate) * dt
    distance = np.cumsum(speed) * dt   # the road changes under a moving vehicle only
    road_pitch = np.radians(2.0) * np.sin(2 * np.pi * distance / 200.0)
    road_roll = np.radians(1.5) * np.sin(2 * np.pi * distance / 120.0 + 1.0)
    roll = road_roll + np.radians(3.0) * a_lat / g
    pitch = road_pitch - np.radians(2.0) * a_lon / g
    body_rate = _euler_rates_to_body(roll, pitch, np.gradient(roll, dt),
                                     np.gradient(pitch, dt), yaw_rate)
    body_acc = np.gradient(body_rate, dt, axis=0)
    rot = _rotation(roll, pitch, yaw)
    a_world = np.stack([np.cos(yaw) * a_lon - np.sin(yaw) * a_lat,
                        np.sin(yaw) * a_lon + np.cos(yaw) * a_lat, np.full_like(t, g)], axis=1)
    force = np.einsum('nji,nj->ni', rot, a_world)
    p = np.asarray(lever_arm_m, dtype=float).reshape(3)
    force += np.cross(body_acc, p) + np.cross(body_rate, np.cross(body_rate, p))
    force /= g
    moving = (speed > 0.05).astype(float)
    vib = np.zeros((t.size, 3))
    gyro_vib = np.zeros((t.size, 3))
    for axis, share in ((0, 1 / 3), (1, 1 / 3), (2, 1.0)):
        freqs = rng.uniform(8.0, 25.0, 6)
        phases = rng.uniform(0, 2 * np.pi, 6)
        wave = np.sin(2 * np.pi * freqs[:, None] * t[None, :] + phases[:, None]).sum(axis=0)
        vib[:, axis] = wave / math.sqrt(3.0) * vibration_g * share
        phases = rng.uniform(0, 2 * np.pi, 6)
        wave = np.sin(2 * np.pi * freqs[:, None] * t[None, :] + phases[:, None]).sum(axis=0)
        gyro_vib[:, axis] = wave / math.sqrt(3.0) * math.radians(0.5)
    force += vib * moving[:, None]
    accel_noise = datasheet_noise_std_g(rate_hz) * noise_scale
    raw = force + rng.standard_normal(force.shape) * accel_noise
    raw = np.round(raw / FULL_RES_G_PER_LSB) * FULL_RES_G_PER_LSB
    ends = np.cumsum([seg[1] for seg in DRIVE_SEGMENTS])
    segment = np.searchsorted(ends, t, side='right')
    stop = [k for k, seg in enumerate(DRIVE_SEGMENTS) if seg[0].startswith('stop')][0]
    stop_start, stop_end = ends[stop] - DRIVE_SEGMENTS[stop][1], ends[stop]
    drift = np.clip((t - stop_start) / (stop_end - stop_start), 0.0, 1.0)
    bias = np.radians(np.array([0.5, -0.4, 0.45]))[None, :] \
        + np.radians(bias_drift_deg_s) * drift[:, None] * np.array([1.0, -1.0, 0.5])
    scale = 1.0 + rng.uniform(-0.01, 0.01, 3)
    gyro_noise = GYRO_NOISE_100HZ_RAD_S * math.sqrt(rate_hz / 100.0) * noise_scale
    white = rng.standard_normal(body_rate.shape) * gyro_noise   # drawn either way (seeds)
    gyro = (body_rate + gyro_vib * moving[:, None]) * scale + bias
    gyro = _gy85_gyro(t, gyro, rate_hz, rng, noise_scale) if gy85 else gyro + white
    odo_t = np.arange(0.0, duration, 1.0 / ODOMETRY_RATE_HZ)
    odo_speed = np.maximum(np.interp(odo_t, t, speed)
                           + rng.standard_normal(odo_t.size) * 0.02 * noise_scale, 0.0)
    odo_yaw = np.interp(odo_t, t, yaw_rate) + rng.standard_normal(odo_t.size) * 0.003 \
        * noise_scale
    return Drive(t, roll, pitch, raw, gyro, odo_t, odo_speed, odo_yaw, segment,
                 (float(p[0]), float(p[1]), float(p[2])), float(rate_hz))


def still_readings(rate_hz: float, seconds: float, roll: float = 0.07, pitch: float = -0.12,
                   seed: int = 0) -> Tuple[np.ndarray, np.ndarray]:
    """Return ``(t, readings g (N, 3))`` of a still, calibrated ADXL345 (datasheet noise)."""
    from accelcal_ros.frames import specific_force_from_roll_pitch

    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / rate_hz)
    force = np.tile(specific_force_from_roll_pitch(roll, pitch), (t.size, 1))
    raw = force + rng.standard_normal(force.shape) * datasheet_noise_std_g(rate_hz)
    return t, np.round(raw / FULL_RES_G_PER_LSB) * FULL_RES_G_PER_LSB
