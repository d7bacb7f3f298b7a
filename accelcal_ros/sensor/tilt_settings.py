"""
Settings of the attitude filter and the small helpers of its averages (pure core).

:class:`FilterSettings` is documented with :mod:`accelcal_ros.sensor.tilt_filter`, which
re-exports it; the node's parameters take their defaults from it.
"""
from dataclasses import dataclass, fields
import math

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
    gyro_time_constant_s: float = 5.0
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
    vertical_aid_time_constant_s: float = 3.0
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


def low_pass_gain(dt: float, tau: float) -> float:
    """Return the gain ``1 - exp(-dt / tau)`` of a first-order low-pass (0 if ``dt`` <= 0)."""
    return 1.0 - math.exp(-dt / tau) if dt > 0.0 else 0.0


def dema_variance_ratio(a: float) -> float:
    """Return sum(h^2) of the double-EMA ``2 EMA - EMA(EMA)`` of white noise, gain ``a``."""
    if a >= 1.0:
        return 1.0
    q = 1.0 - (1.0 - a) ** 2
    return 4.0 * a * a / q - 4.0 * a ** 3 / q ** 2 + a ** 4 * (2.0 - q) / q ** 3
