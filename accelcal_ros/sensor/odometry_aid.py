r"""
The platform's own acceleration at the sensor, from wheel odometry (pure core).

A vehicle's odometry gives its forward speed ``v`` (m/s) and yaw rate ``r`` (rad/s) at
its reference point (nav_msgs/Odometry ``twist.twist.linear.x`` and ``angular.z``, or a
CSV ``t,v,yaw_rate``). In the vehicle frame (REP-103: x forward, y left, z up; the
sensor's axes are taken as the vehicle's) the reference point accelerates by
``(dv/dt, v r, 0)`` (forward, and the centripetal ``v r`` towards the inside of the
turn); the sensor, at the lever arm ``p`` from the reference point, by

``a = (dv/dt - r^2 p_x - (dr/dt) p_y,  v r - r^2 p_y + (dr/dt) p_x,  0)``

(rigid body: ``a_ref + dw/dt x p + w x (w x p)`` with ``w = (0, 0, r)``:
:func:`~accelcal_ros.sensor.lever_arm.rotation_accel`). The tilt filter
subtracts ``a / g`` from the specific force (:class:`~accelcal_ros.sensor.tilt_filter.
AttitudeFilter`), leaving gravity; roll and pitch rates of the body are neglected (their
terms are a few mg on a road vehicle).

Derivatives: ``dv/dt`` and ``dr/dt`` are least-squares slopes over
``derivative_window_s`` (0.4 s: with 0.02 m/s of speed noise at 50 Hz a two-point
difference over 0.1 s would fake 0.03 g, 1.7 deg; the slope over 0.4 s 0.1 deg). Live
(:meth:`OdometryAid.accel_g` with ``centred=False``) the window ends at the query time,
so the acceleration lags by half the window (0.2 s); offline (``centred=True``,
:func:`accel_series_g`, whole recordings) it is centred. Odometry older than
``max_age_s`` (0.5 s) at the query time gives no acceleration (None: the filter then
runs unaided).

Bad input: a message whose time does not increase ("odometry running backwards in time")
or with NaN/infinite values raises :class:`~accelcal_ros.errors.InputError` with the
reason; the message is not used.
"""
import bisect
from collections import deque
import math
from typing import Deque, Optional, Sequence, Tuple

from accelcal_ros.errors import InputError
from accelcal_ros.sensor.lever_arm import check_lever_arm, rotation_accel
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
import numpy as np
from numpy.typing import ArrayLike

KEEP_S = 2.0
"""Odometry kept for the live derivative (s)."""


class OdometryAid:
    """Buffered odometry ``(t, v, yaw_rate)`` -> the acceleration at the sensor (g)."""

    def __init__(self, lever_arm_m: Sequence[float] = (0.0, 0.0, 0.0),
                 derivative_window_s: float = 0.4, max_age_s: float = 0.5) -> None:
        arm = check_lever_arm(lever_arm_m)
        if not (derivative_window_s > 0 and max_age_s > 0):
            raise InputError('derivative_window_s and max_age_s must be positive')
        self.lever_arm_m = tuple(arm)
        self.derivative_window_s = float(derivative_window_s)
        self.max_age_s = float(max_age_s)
        self._t: Deque[float] = deque()
        self._v: Deque[float] = deque()
        self._r: Deque[float] = deque()
        self.used = 0

    @property
    def last_t(self) -> Optional[float]:
        """Return the time (s) of the newest sample kept, or None."""
        return self._t[-1] if self._t else None

    def reset(self) -> None:
        """Forget every sample (the clock jumped back: a bag played again)."""
        self._t.clear()
        self._v.clear()
        self._r.clear()

    def add(self, t_s: float, speed_m_s: float, yaw_rate_rad_s: float) -> None:
        """Add one odometry sample; InputError (not used) if it goes back in time or is NaN."""
        t, v, r = float(t_s), float(speed_m_s), float(yaw_rate_rad_s)
        if not (math.isfinite(t) and math.isfinite(v) and math.isfinite(r)):
            raise InputError(f'odometry at t = {t_s}: NaN or infinite value (v = {speed_m_s}, '
                             f'yaw_rate = {yaw_rate_rad_s}); sample not used')
        if self._t and t <= self._t[-1]:
            raise InputError(f'odometry running backwards in time: t = {t:.6f} s after '
                             f'{self._t[-1]:.6f} s; sample not used (a clock jump or a '
                             'replayed log: restart the node or fix the stamps)')
        self._t.append(t)
        self._v.append(v)
        self._r.append(r)
        self.used += 1
        while len(self._t) > 2 and self._t[0] < t - KEEP_S:
            self._t.popleft()
            self._v.popleft()
            self._r.popleft()

    def _at(self, times: list, values: Deque[float], t: float) -> float:
        k = bisect.bisect_left(times, t)
        if k <= 0:
            return values[0]
        if k >= len(times):
            return values[-1]
        t0, t1 = times[k - 1], times[k]
        w = (t - t0) / (t1 - t0)
        return values[k - 1] + w * (values[k] - values[k - 1])

    def accel_g(self, t_s: float, centred: bool = False
                ) -> Optional[Tuple[float, float, float]]:
        """Return the acceleration at the sensor (g, vehicle frame) at ``t_s``, or None."""
        times = list(self._t)
        if len(times) < 2 or t_s > times[-1] + self.max_age_s \
                or t_s < times[0] - self.max_age_s:
            return None
        w = self.derivative_window_s
        t_end = min(t_s + w / 2.0, times[-1]) if centred else min(t_s, times[-1])
        lo = bisect.bisect_left(times, t_end - w)
        hi = bisect.bisect_right(times, t_end)
        v = self._at(times, self._v, t_s)
        r = self._at(times, self._r, t_s)
        dv = dr = 0.0
        if hi - lo >= 2:
            window = times[lo:hi]
            dv = _slope(window, list(self._v)[lo:hi])
            dr = _slope(window, list(self._r)[lo:hi])
        return _at_sensor(v, r, dv, dr, self.lever_arm_m)


def _slope(t: Sequence[float], y: Sequence[float]) -> float:
    """Least-squares slope of ``y`` over ``t`` (0 if ``t`` has no spread)."""
    n = len(t)
    mt = sum(t) / n
    my = sum(y) / n
    stt = sum((ti - mt) ** 2 for ti in t)
    if stt <= 0.0:
        return 0.0
    return sum((ti - mt) * (yi - my) for ti, yi in zip(t, y)) / stt


def _at_sensor(v: float, r: float, dv: float, dr: float, arm: Sequence[float]
               ) -> Tuple[float, float, float]:
    ax, ay, _ = rotation_accel((0.0, 0.0, r), (0.0, 0.0, dr), arm)
    g = STANDARD_GRAVITY_M_S2
    return (dv + ax) / g, (v * r + ay) / g, 0.0


def _window_slopes(t: np.ndarray, y: np.ndarray, half: float) -> np.ndarray:
    """Least-squares slope of ``y`` in ``[t_k - half, t_k + half]`` at every sample."""
    lo = np.searchsorted(t, t - half, side='left')
    hi = np.searchsorted(t, t + half, side='right')
    tc = t - t[0]

    def window_sum(values):
        c = np.concatenate([[0.0], np.cumsum(values)])
        return c[hi] - c[lo]
    n = (hi - lo).astype(float)
    st, sy = window_sum(tc), window_sum(y)
    stt, sty = window_sum(tc * tc), window_sum(tc * y)
    den = n * stt - st * st
    with np.errstate(invalid='ignore', divide='ignore'):
        slope = (n * sty - st * sy) / den
    return np.where((n >= 2) & (den > 1e-12), slope, 0.0)


def accel_series_g(t_s: ArrayLike, odo_t_s: ArrayLike, speed_m_s: ArrayLike,
                   yaw_rate_rad_s: ArrayLike, lever_arm_m: Sequence[float] = (0.0, 0.0, 0.0),
                   derivative_window_s: float = 0.4) -> np.ndarray:
    """
    Return the acceleration at the sensor (g, (N, 3)) at times ``t_s`` from a whole log.

    Centred derivatives (offline). Rows outside the odometry's span (by more than 0.5 s)
    are NaN. Raises InputError if the odometry's time does not increase.
    """
    t_odo = np.asarray(odo_t_s, dtype=float).reshape(-1)
    v = np.asarray(speed_m_s, dtype=float).reshape(-1)
    r = np.asarray(yaw_rate_rad_s, dtype=float).reshape(-1)
    if not (t_odo.size == v.size == r.size) or t_odo.size < 2:
        raise InputError('odometry needs at least 2 samples of t, v and yaw_rate')
    if not (np.all(np.isfinite(t_odo)) and np.all(np.isfinite(v)) and np.all(np.isfinite(r))):
        raise InputError('odometry contains NaN or infinite values')
    back = np.flatnonzero(np.diff(t_odo) <= 0)
    if back.size:
        k = int(back[0]) + 1
        raise InputError(f'odometry running backwards in time at row {k + 1}: t = '
                         f'{t_odo[k]:.6f} s after {t_odo[k - 1]:.6f} s')
    aid = OdometryAid(lever_arm_m, derivative_window_s)
    t = np.asarray(t_s, dtype=float).reshape(-1)
    half = derivative_window_s / 2.0
    v_t = np.interp(t, t_odo, v)
    r_t = np.interp(t, t_odo, r)
    dv = np.interp(t, t_odo, _window_slopes(t_odo, v, half))
    dr = np.interp(t, t_odo, _window_slopes(t_odo, r, half))
    ax, ay, _ = rotation_accel((0.0, 0.0, r_t), (0.0, 0.0, dr), aid.lever_arm_m)
    out = np.stack([dv + ax, v_t * r_t + ay, np.zeros_like(t)], axis=1) / STANDARD_GRAVITY_M_S2
    outside = (t < t_odo[0] - aid.max_age_s) | (t > t_odo[-1] + aid.max_age_s)
    out[outside] = np.nan
    return out
