r"""
The acceleration a platform's rotation adds at the sensor: the lever arm (pure core).

A rigid platform turning at ``w`` (rad/s, body frame: x forward, y left, z up) with the
angular acceleration ``dw/dt`` moves a point at the lever arm ``p`` (m, from the
platform's reference point, body frame) with the acceleration of the reference point plus

.. math::  a_{rot} = \dot w \times p + w \times (w \times p)

(tangential and centripetal; m/s^2). The accelerometer at ``p`` feels it on top of
gravity; the tilt filter subtracts it (:class:`~accelcal_ros.sensor.tilt_filter.
AttitudeFilter`): with odometry ``w = (0, 0, r)`` from the yaw rate
(:mod:`accelcal_ros.sensor.odometry_aid`), with a gyro alone from the gyro
(:class:`RotationAcceleration`). What is left is the reference point's own acceleration:
for a vehicle whose reference point does not slip sideways (the rear axle's centre),
``(dv/dt, v r, 0)``, so in a steady turn the forward axis again sees gravity alone.
"""
import math
from typing import Any, Optional, Sequence, Tuple

from accelcal_ros.errors import InputError
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2

RATE_TIME_CONSTANT_S = 0.1
"""Low-pass of the gyro rate and of its derivative (s) for :class:`RotationAcceleration`.
The derivative of the rate amplifies its noise and the road's vibration (0.5 deg/s at
8-25 Hz gives 0.9 rad/s^2, 0.09 g at a 1 m lever arm); two first-order low-passes of
0.1 s bring that to a few mg and lag a turn's onset by about 0.2 s. Gyro-alone p95, median
over drive seeds 0-15 at 100 Hz: 0.20 deg at 0.1 s, 0.21 at 0.15 s, 0.26 at 0.3 s (0.20 at
0.05 s over seeds 0-11; 0.26 without the lever arm)."""


def check_lever_arm(lever_arm_m: Any) -> Tuple[float, float, float]:
    """Return ``lever_arm_m`` as 3 finite floats (m); InputError with the reason otherwise."""
    try:
        arm = [float(v) for v in lever_arm_m]
    except (TypeError, ValueError):
        arm = []
    if len(arm) != 3 or not all(math.isfinite(v) for v in arm):
        raise InputError(f'lever_arm_m must be 3 finite numbers (m), got {lever_arm_m!r}')
    return arm[0], arm[1], arm[2]


def rotation_accel(w: Sequence[Any], w_dot: Sequence[Any], p: Sequence[Any]) -> Tuple[Any, ...]:
    """
    Return ``dw/dt x p + w x (w x p)`` per axis (m/s^2 for rad/s, rad/s^2 and m).

    Components may be floats or numpy arrays (broadcast together): one formula for a
    sample and for a whole log.
    """
    wx, wy, wz = w
    ax, ay, az = w_dot
    px, py, pz = p
    cx, cy, cz = wy * pz - wz * py, wz * px - wx * pz, wx * py - wy * px   # w x p
    return (ay * pz - az * py + wy * cz - wz * cy,
            az * px - ax * pz + wz * cx - wx * cz,
            ax * py - ay * px + wx * cy - wy * cx)


class RotationAcceleration:
    """
    The rotation's acceleration at the sensor from a gyro, live (g, body frame).

    :meth:`update` takes each bias-corrected rate; ``w`` is its low-pass and ``dw/dt``
    the low-passed difference of that low-pass (:data:`RATE_TIME_CONSTANT_S` each); the
    result is :func:`rotation_accel` of the two over ``g`` (plain floats: per sample).
    """

    def __init__(self, lever_arm_m: Sequence[float]) -> None:
        self.lever_arm_m = check_lever_arm(lever_arm_m)
        g = STANDARD_GRAVITY_M_S2
        self._p = (self.lever_arm_m[0] / g, self.lever_arm_m[1] / g, self.lever_arm_m[2] / g)
        self._dt = 0.0
        self._gain = (0.0, 0.0)   # a and a / dt for the last dt
        self.reset()

    def reset(self) -> None:
        """Forget the rate history (after a gap in the samples)."""
        self._w: Optional[Tuple[float, float, float]] = None
        self._w_dot = (0.0, 0.0, 0.0)

    def update(self, dt: float, rate_rad_s: Sequence[float]) -> Tuple[float, float, float]:
        """Return ``a_rot / g`` after one rate sample ``dt`` s after the last one."""
        w = self._w
        if w is None:
            self._w = w = (rate_rad_s[0], rate_rad_s[1], rate_rad_s[2])
        elif dt > 0.0:
            if dt != self._dt:
                a = 1.0 - math.exp(-dt / RATE_TIME_CONSTANT_S)
                self._dt, self._gain = dt, (a, a / dt)
            a, c = self._gain
            wx, wy, wz = w
            nx = wx + a * (rate_rad_s[0] - wx)
            ny = wy + a * (rate_rad_s[1] - wy)
            nz = wz + a * (rate_rad_s[2] - wz)
            dx, dy, dz = self._w_dot
            # the low-pass of (new - old) / dt
            self._w_dot = (dx + c * (nx - wx) - a * dx, dy + c * (ny - wy) - a * dy,
                           dz + c * (nz - wz) - a * dz)
            self._w = w = (nx, ny, nz)
        return rotation_accel(w, self._w_dot, self._p)   # type: ignore[return-value]
