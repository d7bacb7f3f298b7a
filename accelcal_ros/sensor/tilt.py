r"""
Tilt (roll and pitch) from a calibrated accelerometer, with its covariance (pure core).

Shared by the ``attitude`` node and ``accelcal attitude`` (offline), so it lives here,
below both.

Input: raw readings ``a`` in g (sensor frame, x forward, y left, z up; REP-145 +1 g up
at rest). The calibration (:class:`~accelcal_ros.sensor.model.SensorModel`) gives
the specific force ``f = T diag(1/k) (a - b)``; then (REP-103, radians)
``roll = atan2(f_y, f_z)``, ``pitch = atan2(-f_x, sqrt(f_y^2 + f_z^2))``
(:func:`accelcal_ros.frames.roll_pitch_from_specific_force`; paper A eqs. 2-3 with the
sign mapping of :mod:`accelcal_ros.frames`). Pitch is finite everywhere; at pitch
+-90 deg roll is undefined, comes out 0 (never NaN) and its variance is capped at pi^2.

Smoothing (``time_constant_s`` > 0): a first-order low-pass on ``f`` (not on the angles,
so nothing wraps), ``f_s += alpha (f - f_s)``, ``alpha = 1 - exp(-dt / tau)``.

Covariance of (roll, pitch): the sensor noise ``Sigma_a`` propagated through the
correction and the angle equations, ``J C Sigma_a C^T J^T`` (scaled by
``alpha / (2 - alpha)`` when smoothed), plus the calibration's own uncertainty
``tilt_std_rad^2`` on both angles (from the calibration file's predicted error).

Acceleration: when ``| |f| - 1 |`` exceeds ``accel_threshold_g`` the sensor is not
measuring gravity alone. The estimate is then flagged, the last good roll/pitch is held,
and the variance is inflated by ``asin(min(1, | |f| - 1 |))^2`` -- the tilt an
acceleration of that size could fake. A hold lasts at most ``max_hold_s``: a magnitude
that stays off 1 g (an uncalibrated or wrongly calibrated sensor) is not an acceleration,
so after that the measured tilt is published again, still flagged and inflated. Without
a calibration (the identity model) nothing is held: a raw ADXL345 reads 0.85-1.15 g at
rest, so the magnitude says nothing about acceleration.
"""
from dataclasses import dataclass
import math

from accelcal_ros.errors import InputError
from accelcal_ros.frames import roll_pitch_from_specific_force
from accelcal_ros.sensor.datasheet import NOISE_STD_100HZ_G
from accelcal_ros.sensor.model import SensorModel
import numpy as np

ROLL_VARIANCE_CAP = math.pi ** 2
"""Roll variance reported where roll is undefined (pitch at +-90 deg)."""


@dataclass
class TiltEstimate:
    """One output of :class:`TiltEstimator`; angles in rad, force in g."""

    stamp: float
    roll: float
    pitch: float
    force_g: np.ndarray
    """Calibrated specific force (g), not smoothed."""
    covariance: np.ndarray
    """2x2 covariance of (roll, pitch), rad^2."""
    accelerating: bool
    magnitude_g: float


def angle_jacobian(force):
    """
    Return d(roll, pitch)/d f (2x3) at specific force ``force``, finite everywhere.

    Where ``f_y = f_z = 0`` (pitch +-90 deg) the roll row is 0; the caller caps the roll
    variance there.
    """
    fx, fy, fz = (float(v) for v in force)
    h2 = fy * fy + fz * fz
    h = math.sqrt(h2)
    n2 = fx * fx + h2
    jac = np.zeros((2, 3))
    if h2 > 1e-18:
        jac[0, 1] = fz / h2
        jac[0, 2] = -fy / h2
    if n2 > 1e-18:
        jac[1, 0] = -h / n2
        if h > 1e-9:
            jac[1, 1] = fx * fy / (h * n2)
            jac[1, 2] = fx * fz / (h * n2)
    return jac


def quaternion_from_roll_pitch(roll, pitch):
    """Return the quaternion ``(x, y, z, w)`` of ``Ry(pitch) Rx(roll)`` (yaw 0, REP-103)."""
    cr, sr = math.cos(roll / 2.0), math.sin(roll / 2.0)
    cp, sp = math.cos(pitch / 2.0), math.sin(pitch / 2.0)
    return (cp * sr, sp * cr, -sp * sr, cp * cr)


class TiltEstimator:
    """Calibrated roll/pitch with covariance, smoothing and an acceleration flag."""

    def __init__(self, sensor_model=None, noise_std_g=NOISE_STD_100HZ_G,
                 tilt_std_rad=0.0, time_constant_s=0.0, accel_threshold_g=0.05,
                 max_hold_s=1.0):
        self.set_calibration(sensor_model or SensorModel.identity())
        self.set_noise(noise_std_g)
        self.tilt_std_rad = float(tilt_std_rad)
        self.time_constant_s = 0.0
        if time_constant_s < 0 or accel_threshold_g <= 0:
            raise InputError('time_constant_s must be >= 0 and accel_threshold_g > 0')
        self.time_constant_s = float(time_constant_s)
        self.accel_threshold_g = float(accel_threshold_g)
        self.max_hold_s = float(max_hold_s)
        self.reset()

    def reset(self):
        """Forget the filter state and the held estimate."""
        self._smoothed = None
        self._last_t = None
        self._held = None
        self._hold_start = None

    def set_noise(self, noise_std_g):
        """Set the per-axis raw noise standard deviation (g)."""
        noise = np.asarray(noise_std_g, dtype=float).reshape(-1)
        if noise.shape != (3,) or not np.all(np.isfinite(noise)) or np.any(noise < 0):
            raise InputError(f'noise_std_g must be 3 non-negative numbers, got {noise_std_g}')
        self._noise_cov = np.diag(noise ** 2)

    def force_covariance_g2(self):
        """Return the 3x3 noise covariance of the calibrated force, ``C Sigma_a C^T`` (g^2)."""
        return self._correction @ self._noise_cov @ self._correction.T

    def set_calibration(self, sensor_model, tilt_std_rad=None):
        """Use a new calibration from now on (the filter restarts)."""
        self.sensor_model = sensor_model
        self._correction = sensor_model.correction_matrix()
        identity = SensorModel.identity()
        self.calibrated = not (np.array_equal(sensor_model.scale, identity.scale)
                               and np.array_equal(sensor_model.bias, identity.bias)
                               and np.array_equal(sensor_model.misalignment,
                                                  identity.misalignment))
        if tilt_std_rad is not None:
            self.tilt_std_rad = float(tilt_std_rad)
        self.reset()

    def update(self, stamp, raw_g):
        """
        Return the :class:`TiltEstimate` for one raw reading (g) at ``stamp`` (s).

        Returns None for a NaN/infinite reading (nothing to estimate from).
        """
        raw = np.asarray(raw_g, dtype=float).reshape(3)
        if not np.all(np.isfinite(raw)):
            return None
        correction = self._correction
        force = correction @ (raw - self.sensor_model.bias)
        magnitude = float(np.linalg.norm(force))
        deviation = abs(magnitude - 1.0)
        accelerating = deviation > self.accel_threshold_g
        alpha = 1.0
        if self.time_constant_s > 0.0 and self._smoothed is not None \
                and self._last_t is not None and stamp > self._last_t:
            alpha = 1.0 - math.exp(-(stamp - self._last_t) / self.time_constant_s)
        self._last_t = stamp
        if not accelerating:
            self._hold_start = None
        elif self._hold_start is None:
            self._hold_start = stamp
        holding = accelerating and self._held is not None and self.calibrated \
            and stamp - self._hold_start <= self.max_hold_s
        if holding:
            roll, pitch, base_cov = self._held
            extra = math.asin(min(1.0, deviation)) ** 2
            cov = base_cov + np.eye(2) * extra
            return TiltEstimate(stamp, roll, pitch, force, cov, True, magnitude)
        if self._smoothed is None or alpha >= 1.0:
            self._smoothed = force.copy()
        else:
            self._smoothed += alpha * (force - self._smoothed)
        roll, pitch = (float(v) for v in roll_pitch_from_specific_force(self._smoothed))
        jac = angle_jacobian(self._smoothed / max(np.linalg.norm(self._smoothed), 1e-12))
        force_cov = self.force_covariance_g2()
        cov = jac @ force_cov @ jac.T
        if self.time_constant_s > 0.0:
            cov *= alpha / (2.0 - alpha) if alpha < 1.0 else 1.0
        cov += np.eye(2) * self.tilt_std_rad ** 2
        if jac[0, 1] == 0.0 and jac[0, 2] == 0.0 or cov[0, 0] > ROLL_VARIANCE_CAP:
            cov[0, 0] = ROLL_VARIANCE_CAP
            cov[0, 1] = cov[1, 0] = 0.0
        if accelerating:
            cov = cov + np.eye(2) * math.asin(min(1.0, deviation)) ** 2
        else:
            self._held = (roll, pitch, cov.copy())
        return TiltEstimate(stamp, roll, pitch, force, cov, accelerating, magnitude)


def estimate_many(estimator, t, raw_g):
    """Run ``estimator`` over samples ``t`` (N,), ``raw_g`` (N, 3); returns the estimates."""
    t = np.asarray(t, dtype=float)
    raw_g = np.asarray(raw_g, dtype=float)
    return [estimator.update(ti, ai) for ti, ai in zip(t, raw_g)]
