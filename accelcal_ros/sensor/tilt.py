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

Impossible input: a reading that is NaN or infinite, exactly zero (a read glitch), or
whose calibrated magnitude is below :data:`MIN_FORCE_G` (no usable direction: free fall)
or above :data:`MAX_FORCE_G` (no accelerometer reads that: a corrupt value such as
1e300), gives no estimate
(:meth:`TiltEstimator.update` returns None) and :attr:`TiltEstimator.last_rejection`
says why; nothing is published for it.

Cost: the per-sample path works on plain floats (the 3-vectors and the 2x2 covariance),
which in CPython is several times cheaper than numpy on arrays this small.
"""
import math
from typing import Optional, Sequence, Tuple

from accelcal_ros.errors import InputError
from accelcal_ros.sensor.datasheet import NOISE_STD_100HZ_G
from accelcal_ros.sensor.model import SensorModel
import numpy as np

ROLL_VARIANCE_CAP = math.pi ** 2
"""Roll variance reported where roll is undefined (pitch at +-90 deg)."""
MIN_FORCE_G = 0.1
"""Below this calibrated magnitude (g) the direction of ``f`` is mostly noise and bias (a
zero reading, free fall): no tilt is estimated from it."""
MAX_FORCE_G = 1000.0
"""Above this calibrated magnitude (g) a reading is corrupt, not an acceleration."""


class TiltEstimate:
    """One output of :class:`TiltEstimator`; angles in rad, force in g (plain floats)."""

    __slots__ = ('stamp', 'roll', 'pitch', 'force', 'cov', 'accelerating', 'magnitude_g')

    def __init__(self, stamp: float, roll: float, pitch: float,
                 force: Tuple[float, float, float], cov: Tuple[float, float, float],
                 accelerating: bool, magnitude_g: float) -> None:
        self.stamp = stamp
        self.roll = roll
        self.pitch = pitch
        self.force = force
        """Calibrated specific force (g), not smoothed."""
        self.cov = cov
        """Covariance of (roll, pitch) as ``(var_roll, cov_roll_pitch, var_pitch)``, rad^2."""
        self.accelerating = accelerating
        self.magnitude_g = magnitude_g

    @property
    def force_g(self) -> np.ndarray:
        """Return the calibrated specific force (g) as an array."""
        return np.array(self.force)

    @property
    def covariance(self) -> np.ndarray:
        """Return the 2x2 covariance of (roll, pitch), rad^2."""
        c00, c01, c11 = self.cov
        return np.array([[c00, c01], [c01, c11]])


def _jacobian_rows(fx: float, fy: float, fz: float) -> Tuple[float, ...]:
    """Return ``(r1, r2, p0, p1, p2)``: the non-zero entries of d(roll, pitch)/d f."""
    h2 = fy * fy + fz * fz
    h = math.sqrt(h2)
    n2 = fx * fx + h2
    r1 = r2 = p0 = p1 = p2 = 0.0
    if h2 > 1e-18:
        r1 = fz / h2
        r2 = -fy / h2
    if n2 > 1e-18:
        p0 = -h / n2
        if h > 1e-9:
            p1 = fx * fy / (h * n2)
            p2 = fx * fz / (h * n2)
    return r1, r2, p0, p1, p2


def angle_jacobian(force: Sequence[float]) -> np.ndarray:
    """
    Return d(roll, pitch)/d f (2x3) at specific force ``force``, finite everywhere.

    Where ``f_y = f_z = 0`` (pitch +-90 deg) the roll row is 0; the caller caps the roll
    variance there.
    """
    r1, r2, p0, p1, p2 = _jacobian_rows(*(float(v) for v in force))
    return np.array([[0.0, r1, r2], [p0, p1, p2]])


def quaternion_from_roll_pitch(roll: float, pitch: float) -> Tuple[float, float, float, float]:
    """Return the quaternion ``(x, y, z, w)`` of ``Ry(pitch) Rx(roll)`` (yaw 0, REP-103)."""
    cr, sr = math.cos(roll / 2.0), math.sin(roll / 2.0)
    cp, sp = math.cos(pitch / 2.0), math.sin(pitch / 2.0)
    return (cp * sr, sp * cr, -sp * sr, cp * cr)


class AccelerationHold:
    """
    The last steady tilt, held while the force is not gravity alone (one home for both estimators).

    :meth:`estimate` is called for every reading: while ``accelerating`` it returns the
    held ``(roll, pitch, cov)`` as a flagged :class:`TiltEstimate`, its variances inflated
    by ``asin(min(1, deviation))^2`` (rad^2; ``deviation = | |f| - 1 |`` in g), for at
    most ``max_hold_s`` seconds from the first accelerating reading, and only when
    calibrated (module docstring: "Acceleration"); otherwise None and the caller
    estimates. :attr:`held` is what the caller stores after a steady reading.
    """

    __slots__ = ('held', 'start')

    def __init__(self) -> None:
        self.held: Optional[Tuple[float, float, Tuple[float, float, float]]] = None
        """The last steady ``(roll, pitch, (c00, c01, c11))``, rad and rad^2."""
        self.start: Optional[float] = None
        """Stamp (s) of the first reading of the current acceleration (None when steady)."""

    def estimate(self, stamp: float, accelerating: bool, calibrated: bool, max_hold_s: float,
                 force: Tuple[float, float, float], magnitude_g: float,
                 deviation_g: float) -> Optional[TiltEstimate]:
        """Return the held estimate for a reading at ``stamp`` (s), or None (see class)."""
        if not accelerating:
            self.start = None
            return None
        if self.start is None:
            self.start = stamp
        if self.held is None or not calibrated or stamp - self.start > max_hold_s:
            return None
        roll, pitch, (c00, c01, c11) = self.held
        extra = math.asin(min(1.0, deviation_g)) ** 2
        return TiltEstimate(stamp, roll, pitch, force, (c00 + extra, c01, c11 + extra),
                            True, magnitude_g)


class TiltEstimator:
    """Calibrated roll/pitch with covariance, smoothing and an acceleration flag."""

    def __init__(self, sensor_model: Optional[SensorModel] = None,
                 noise_std_g: Sequence[float] = NOISE_STD_100HZ_G, tilt_std_rad: float = 0.0,
                 time_constant_s: float = 0.0, accel_threshold_g: float = 0.05,
                 max_hold_s: float = 1.0) -> None:
        self._noise_cov = np.eye(3)
        self.set_calibration(sensor_model or SensorModel.identity())
        self.set_noise(noise_std_g)
        self.tilt_std_rad = float(tilt_std_rad)
        self.time_constant_s = 0.0
        if time_constant_s < 0 or accel_threshold_g <= 0:
            raise InputError('time_constant_s must be >= 0 and accel_threshold_g > 0')
        self.time_constant_s = float(time_constant_s)
        self.accel_threshold_g = float(accel_threshold_g)
        self.max_hold_s = float(max_hold_s)
        self.last_rejection = ''
        """Why the last None was returned: 'NaN', 'zero' or 'out of range' ('' if none)."""
        self.reset()

    def reset(self) -> None:
        """Forget the filter state and the held estimate."""
        self._smoothed: Optional[Tuple[float, float, float]] = None
        self._last_t: Optional[float] = None
        self._hold = AccelerationHold()

    def set_noise(self, noise_std_g: Sequence[float]) -> None:
        """Set the per-axis raw noise standard deviation (g)."""
        noise = np.asarray(noise_std_g, dtype=float).reshape(-1)
        if noise.shape != (3,) or not np.all(np.isfinite(noise)) or np.any(noise < 0):
            raise InputError(f'noise_std_g must be 3 non-negative numbers, got {noise_std_g}')
        self._noise_cov = np.diag(noise ** 2)
        self._update_force_covariance()

    def force_covariance_g2(self) -> np.ndarray:
        """Return the 3x3 noise covariance of the calibrated force, ``C Sigma_a C^T`` (g^2)."""
        return self._force_cov.copy()

    @property
    def force_covariance_list_g2(self) -> list:
        """Return ``C Sigma_a C^T`` (g^2) row-major as a list; a new list when it changes."""
        return self._force_cov_list

    def _update_force_covariance(self) -> None:
        self._force_cov = self._correction @ self._noise_cov @ self._correction.T
        self._force_cov_list = self._force_cov.ravel().tolist()

    def set_calibration(self, sensor_model: SensorModel,
                        tilt_std_rad: Optional[float] = None) -> None:
        """Use a new calibration from now on (the filter restarts)."""
        self.sensor_model = sensor_model
        self._correction = sensor_model.correction_matrix()
        self._c = self._correction.ravel().tolist()
        self._b = sensor_model.bias.tolist()
        self.calibrated = not sensor_model.is_identity()
        if tilt_std_rad is not None:
            self.tilt_std_rad = float(tilt_std_rad)
        self._update_force_covariance()
        self.reset()

    def correct(self, raw_g: Sequence[float]
                ) -> Optional[Tuple[float, float, float, float]]:
        """
        Return ``(f_x, f_y, f_z, |f|)``, the calibrated specific force (g), or None.

        None for impossible input (see the module docstring); :attr:`last_rejection` says
        why.
        """
        ax, ay, az = raw_g
        ax, ay, az = float(ax), float(ay), float(az)
        if not math.isfinite(ax + ay + az) or not math.isfinite(ax * ax + ay * ay + az * az):
            self.last_rejection = 'NaN' if math.isnan(ax + ay + az) else 'out of range'
            return None
        if ax == 0.0 and ay == 0.0 and az == 0.0:
            self.last_rejection = 'zero'
            return None
        b = self._b
        dx, dy, dz = ax - b[0], ay - b[1], az - b[2]
        c = self._c
        fx = c[0] * dx + c[1] * dy + c[2] * dz
        fy = c[3] * dx + c[4] * dy + c[5] * dz
        fz = c[6] * dx + c[7] * dy + c[8] * dz
        magnitude = math.sqrt(fx * fx + fy * fy + fz * fz)
        if not MIN_FORCE_G <= magnitude <= MAX_FORCE_G:
            self.last_rejection = 'zero' if magnitude < MIN_FORCE_G else 'out of range'
            return None
        return fx, fy, fz, magnitude

    def angles_with_covariance(self, sx: float, sy: float, sz: float, shrink: float = 1.0
                               ) -> Tuple[float, float, Tuple[float, float, float]]:
        """
        Return ``(roll, pitch, (var_roll, cov, var_pitch))`` of a specific force ``s`` (g).

        The covariance is the force noise propagated through the angle equations, times
        ``shrink`` (the variance ratio of an average: ``alpha / (2 - alpha)`` for a
        low-pass, ``1 / n`` for a mean), plus ``tilt_std_rad^2``; roll's is capped where
        it is undefined.
        """
        hyz = math.hypot(sy, sz)
        roll = math.atan2(sy, sz)
        pitch = math.atan2(-sx, hyz)
        norm = max(math.sqrt(sx * sx + hyz * hyz), 1e-12)
        r1, r2, p0, p1, p2 = _jacobian_rows(sx / norm, sy / norm, sz / norm)
        # cov = J S J^T with J = [[0, r1, r2], [p0, p1, p2]] and S the force covariance.
        s = self._force_cov_list
        sr0 = s[1] * r1 + s[2] * r2
        sr1 = s[4] * r1 + s[5] * r2
        sr2 = s[7] * r1 + s[8] * r2
        c00 = r1 * sr1 + r2 * sr2
        c01 = p0 * sr0 + p1 * sr1 + p2 * sr2
        c11 = (p0 * (s[0] * p0 + s[1] * p1 + s[2] * p2)
               + p1 * (s[3] * p0 + s[4] * p1 + s[5] * p2)
               + p2 * (s[6] * p0 + s[7] * p1 + s[8] * p2))
        if shrink != 1.0:
            c00, c01, c11 = c00 * shrink, c01 * shrink, c11 * shrink
        extra = self.tilt_std_rad ** 2
        c00 += extra
        c11 += extra
        if r1 == 0.0 and r2 == 0.0 or c00 > ROLL_VARIANCE_CAP:
            c00, c01 = ROLL_VARIANCE_CAP, 0.0
        return roll, pitch, (c00, c01, c11)

    def update(self, stamp: float, raw_g: Sequence[float]) -> Optional[TiltEstimate]:
        """
        Return the :class:`TiltEstimate` for one raw reading (g) at ``stamp`` (s).

        Returns None for impossible input (NaN/infinite, zero or absurd magnitude; see the
        module docstring) and sets :attr:`last_rejection`.
        """
        corrected = self.correct(raw_g)
        if corrected is None:
            return None
        fx, fy, fz, magnitude = corrected
        force = (fx, fy, fz)
        deviation = abs(magnitude - 1.0)
        accelerating = deviation > self.accel_threshold_g
        tau = self.time_constant_s
        alpha = 1.0
        if tau > 0.0 and self._smoothed is not None \
                and self._last_t is not None and stamp > self._last_t:
            alpha = 1.0 - math.exp(-(stamp - self._last_t) / tau)
        self._last_t = stamp
        held = self._hold.estimate(stamp, accelerating, self.calibrated, self.max_hold_s,
                                   force, magnitude, deviation)
        if held is not None:
            return held
        if self._smoothed is None or alpha >= 1.0:
            sx, sy, sz = force
        else:
            px, py, pz = self._smoothed
            sx, sy, sz = px + alpha * (fx - px), py + alpha * (fy - py), pz + alpha * (fz - pz)
        self._smoothed = (sx, sy, sz)
        shrink = alpha / (2.0 - alpha) if tau > 0.0 and alpha < 1.0 else 1.0
        roll, pitch, (c00, c01, c11) = self.angles_with_covariance(sx, sy, sz, shrink)
        if accelerating:
            extra = math.asin(min(1.0, deviation)) ** 2
            c00 += extra
            c11 += extra
        else:
            self._hold.held = (roll, pitch, (c00, c01, c11))
        return TiltEstimate(stamp, roll, pitch, force, (c00, c01, c11), accelerating,
                            magnitude)


def estimate_many(estimator: TiltEstimator, t: Sequence[float],
                  raw_g: Sequence[Sequence[float]]) -> list:
    """Run ``estimator`` over samples ``t`` (N,), ``raw_g`` (N, 3); returns the estimates."""
    t = np.asarray(t, dtype=float).tolist()
    raw_g = np.asarray(raw_g, dtype=float).reshape(-1, 3).tolist()
    return [estimator.update(ti, ai) for ti, ai in zip(t, raw_g)]
