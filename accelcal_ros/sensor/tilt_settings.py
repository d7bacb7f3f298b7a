"""
Settings of the attitude filter and its small helpers: averages, bad gyro samples (pure core).

:class:`FilterSettings` is documented with :mod:`accelcal_ros.sensor.tilt_filter`, which
re-exports it; the node's parameters take their defaults from it.

Covariance: the noise propagated as in :class:`TiltEstimator`, times the variance ratio of
the average (``(4 n - 2) / (n (n + 1))`` for the end of a line through n samples, the
double low-pass's sum of squared weights), plus the calibration's ``tilt_std_rad^2``.

**Honest when blind.** The accelerometer cannot tell gravity from a steady acceleration.
While moving without an aid, the variance gains ``max(asin(| |f| - 1 |), atan(s))^2`` with
``s`` the detector's spread of 20 ms means (g): the tilt that the motion seen could fake.
On a platform that may accelerate steadily (``platform_accel_g`` > 0: a vehicle, a mast on
a ship) a steady turn looks still, so the variance gains ``atan(platform_accel_g)^2`` on
every sample unless odometry or a gyro is used; :attr:`AttitudeFilter.mode` says which case
applies. ``| |f_fast| - 1 |`` above ``accel_threshold_g`` (calibrated sensors only; single
samples at 800 Hz would cross 0.05 g by noise) holds the last good tilt (at most
``max_hold_s``), as :class:`TiltEstimator` does.
"""
from dataclasses import dataclass, fields
import math
from typing import Dict, List, Optional, Sequence, Tuple

from accelcal_ros.errors import InputError


@dataclass(frozen=True)
class FilterSettings:
    """Every setting of :class:`AttitudeFilter` (see the module docstring)."""

    still_time_constant_s: float = 2.0
    """Time constant of the average while still (s)."""
    moving_time_constant_s: float = 0.04
    """Time constant of the low-pass used while moving (s): its lag."""
    jump_sigma: float = 5.0
    """A still average further than this many standard deviations of the fast one restarts."""
    gyro_time_constant_s: float = 3.0
    """Complementary filter: time constant of the pull towards the accelerometer (s)."""
    rejection_deg: float = 2.0
    """Innovation beyond which the accelerometer is ignored (the platform accelerates; deg)."""
    rejection_timeout_s: float = 20.0
    """Longest time the accelerometer is ignored before it is trusted again (s)."""
    bias_time_constant_s: float = 30.0
    """Memory of the gyro bias estimate within one still period (s; its line fit)."""
    gyro_noise_std_rad_s: float = 0.0066
    """Gyro noise per sample (rad/s; ITG-3205: 0.38 deg/s rms)."""
    gyro_bias_drift_rad_s2: float = 7.0e-4
    """Drift of the gyro bias (rad/s per s: 0.04 deg/s^2, a warm-up): the prior of the bias
    line's slope while still and the growth of its uncertainty away from stillness."""
    gyro_saturation_rad_s: float = 34.9
    """A rate at or beyond this on an axis is saturated (rad/s; ITG-3205: 2000 deg/s)."""
    platform_accel_g: float = 0.0
    """Steady acceleration the platform may have (g; 0: the rig does not ride a vehicle)."""
    odometry_accel_std_g: float = 0.02
    """Uncertainty of the platform acceleration derived from odometry (g)."""
    odometry_time_constant_s: float = 0.5
    """The low-pass while moving when odometry removes the platform's acceleration (s):
    what is left is vibration and odometry noise (0.04 s would pass 0.3 deg of it), and
    the double low-pass does not lag behind the body's steady roll in a turn."""
    vertical_aid_time_constant_s: float = 2.5
    """While the accelerometer is rejected, the pull along the horizontal acceleration from
    the specific force's vertical component staying 1 g (s; 0: off; a vehicle)."""

    def check(self) -> None:
        """Raise InputError naming the first setting out of its range."""
        zero_ok = ('platform_accel_g', 'gyro_bias_drift_rad_s2', 'odometry_accel_std_g',
                   'gyro_noise_std_rad_s', 'vertical_aid_time_constant_s')
        for item in fields(self):
            value = getattr(self, item.name)
            ok = isinstance(value, (int, float)) and math.isfinite(value) and (
                value >= 0.0 if item.name in zero_ok else value > 0.0)
            if not ok:
                kind = 'non-negative' if item.name in zero_ok else 'positive'
                raise InputError(f'attitude filter setting {item.name} must be a {kind} '
                                 f'number, got {value!r}')
        if self.platform_accel_g > 1.0:
            raise InputError('platform_accel_g must be at most 1 g, got '
                             f'{self.platform_accel_g!r}')


# -- fixed constants of the gyro path (AttitudeFilter) ------------------------------------
GYRO_HOLD_S = 0.1
"""A bad or missing gyro sample is bridged with the last good rate for at most this (s)."""
INNOVATION_TIME_CONSTANT_S = 0.1
"""Low-pass of the innovation that the acceleration rejection tests (s)."""
BIAS_MIN_BLOCKS = 10
"""20 ms blocks of stillness needed before the gyro bias is known (0.2 s)."""
MAX_GAP_S = 0.5
"""A larger gap between samples restarts the gyro state (s)."""
BIAS_INTEGRAL_TIME_CONSTANT_S = 5.0
"""Moving, accelerometer trusted: the integral term's gain ``ki = dt / (this * tau)``
(s; ``tau``: ``gyro_time_constant_s``): the loop ``s^2 + s / tau + 1 / (this * tau)``,
damping 0.65 at tau = 3 s."""
G_SCALE_TIME_CONSTANT_S = 60.0
"""Memory of the specific force along "up" at rest (the 1 g the vertical aid expects)."""
VERTICAL_AID_MIN_G = 0.03
"""Horizontal acceleration below which the vertical aid tells nothing (g)."""
VERTICAL_AID_FULL_G = 0.2
"""Horizontal acceleration from which the vertical aid has its full gain (g); below, the
gain falls with its square (the information it carries against vibration and noise)."""
TURN_RATE_RAD_S = 0.16
"""Rotation about "up" beyond this (9 deg/s) is a turn: a sensor 2 m from the rotation
axis then feels 0.005 g of centripetal acceleration on any axis (0.3 deg), so the
accelerometer is trusted on no axis (odometry, when given, removes it)."""
BIAS_RATE_LIMIT_RAD_S = 0.01
"""Stillness with a known bias: the mean corrected rate below this (0.57 deg/s). The
detector's default (0.05 rad/s) lets a vehicle cruising over a changing grade (0.5 deg/s
of pitch rate) pass as still, and its rate would be learnt as bias."""

BIAS_INNOVATION_LIMIT_RAD = math.radians(0.5)
"""The bias is learnt only while the accelerometer agrees with the gyro this well."""
UNDO_TIME_CONSTANT_S = 0.5
"""Corrections this recent (exponential weight, s) are taken back when a rejection starts."""
STILL_RECOVERY_S = 1.0
"""Still (odometry: stopped) but rejecting this long: the estimate drifted during a long
manoeuvre; the accelerometer is trusted again."""
STILL_RECOVERY_UNAIDED_S = 3.0
"""The same without odometry (a steady pull on a smooth road also looks still)."""
RECOVERY_STILL_S = 1.0
"""That recovery needs this long a stillness (s; the detector's ``min_still_s``): a steady
pull passes the detector now and then for a block or two."""
RECOVERY_FORCE_G = 0.003
"""And the still average's magnitude within this of the 1 g at rest (g): a steady pull of
``a`` g on a smooth road passes the detector for seconds, but ``|f| = sqrt(1 + a^2)``
(0.1 g: 0.005 g over; the average's noise over 1 s: 0.0004 g)."""
AT_REST_AFTER_S = 0.3
"""Stillness this old (s) before the gyro path's at-rest update trusts the accelerometer (a
Kalman gain with the variance propagated while moving, then the still average). On a
smooth road a cruise, or the first tens of ms of a braking, passes the stillness detector
for a block or two: at once, with the variance grown while moving, that update snapped to
the acceleration (1-1.7 deg; drive seeds 0-7, vibration 0 and 0.01 g, gyro alone: p95
worst 1.16-1.39 -> 0.35-0.38 deg, max 1.50-1.70 -> 0.40-0.44 deg; 1 s did the same)."""
STILL_RECOVERY_TIME_CONSTANT_S = 0.5
"""Time constant of that recovery (s)."""
STILL_ROTATION_RAD_S = math.radians(0.1)
"""The gyro bias is learnt only from a still line whose direction is shown to turn slower
than this (its slope across it, plus 2 sigma; g/s ~ rad/s): on a smooth road a vehicle
cruising over a changing grade or bank (0.3-0.5 deg/s) passes the stillness detector, and
its rate would be learnt as bias."""


class GyroHold:
    """The rate to use for a sample: a bad one (NaN, infinite, saturated) bridged for a while."""

    def __init__(self) -> None:
        self.rejections: Dict[str, int] = {'NaN': 0, 'saturated': 0}
        """Bad samples by reason."""
        self.last: Optional[Tuple[float, float, float, float]] = None
        """The last good sample ``(t, x, y, z)``."""

    def rate(self, stamp: float, gyro_rad_s: Optional[Sequence[float]],
             saturation_rad_s: float) -> Optional[Tuple[float, float, float]]:
        """Return the rate to use at ``stamp`` (a bad one: the last good, :data:`GYRO_HOLD_S`)."""
        if gyro_rad_s is None:
            return None
        gx, gy, gz = float(gyro_rad_s[0]), float(gyro_rad_s[1]), float(gyro_rad_s[2])
        reason = ''
        if not math.isfinite(gx + gy + gz):
            reason = 'NaN'
        elif abs(gx) >= saturation_rad_s or abs(gy) >= saturation_rad_s \
                or abs(gz) >= saturation_rad_s:
            reason = 'saturated'
        if not reason:
            self.last = (stamp, gx, gy, gz)
            return gx, gy, gz
        self.rejections[reason] += 1
        last = self.last
        if last is not None and 0.0 <= stamp - last[0] <= GYRO_HOLD_S:
            return last[1], last[2], last[3]
        return None


def still_turning(level: Sequence[float], slope: Sequence[float], slope_var_ratio: float,
                  cov: Sequence[float]) -> Tuple[bool, bool]:
    """
    Return whether a still line (``level``, ``slope`` per s; g) turns, is shown at rest.

    Its slope across its direction (g/s ~ rad/s) per axis against
    :data:`STILL_ROTATION_RAD_S`: beyond it by 3 sigma on an axis (turning), below it by 2
    sigma on every axis (at rest); ``slope_var_ratio``: the slope's variance per unit of a
    sample's (``cov``: the force's 3x3 covariance, row-major, g^2).
    """
    size = math.sqrt(level[0] ** 2 + level[1] ** 2 + level[2] ** 2)
    u = [x / size for x in level]
    along = slope[0] * u[0] + slope[1] * u[1] + slope[2] * u[2]
    across = [abs(m - along * x) for m, x in zip(slope, u)]
    sigma = [math.sqrt(cov[4 * k] * slope_var_ratio) for k in range(3)]
    lim = STILL_ROTATION_RAD_S
    return (any(m - 3.0 * e > lim for m, e in zip(across, sigma)),
            all(m + 2.0 * e < lim for m, e in zip(across, sigma)))


def holt_slope(s1: Sequence[float], s2: Sequence[float], a: float, dt: float
               ) -> Tuple[List[float], float]:
    """
    Return the slope (per s) of the double low-pass ``s1``, ``s2`` (gain ``a``), variance ratio.

    A ramp ``m`` leaves ``s1 - s2 = m dt (1 - a) / a``; the slope's variance per unit of
    a sample's is ``2 a^3 / (dt^2 (2 - a)^3)`` (the sum of its squared weights).
    """
    c = a / ((1.0 - a) * dt)
    return ([(s1[k] - s2[k]) * c for k in range(3)],
            2.0 * a ** 3 / (dt * dt * (2.0 - a) ** 3))


def low_pass_gain(dt: float, tau: float) -> float:
    """Return the gain ``1 - exp(-dt / tau)`` of a first-order low-pass (0 if ``dt`` <= 0)."""
    return 1.0 - math.exp(-dt / tau) if dt > 0.0 else 0.0


def dema_variance_ratio(a: float) -> float:
    """Return sum(h^2) of the double-EMA ``2 EMA - EMA(EMA)`` of white noise, gain ``a``."""
    if a >= 1.0:
        return 1.0
    q = 1.0 - (1.0 - a) ** 2
    return 4.0 * a * a / q - 4.0 * a ** 3 / q ** 2 + a ** 4 * (2.0 - q) / q ** 3
