r"""
Roll and pitch a panorama can use: steady at rest, aided in motion (pure core).

:class:`AttitudeFilter` turns a stream of accelerometer samples (raw, g; REP-145 +1 g up at
rest), optionally with angular velocity (rad/s, same body frame, x forward, y left, z up)
and the platform's own acceleration (g, from odometry:
:mod:`accelcal_ros.sensor.odometry_aid`), into roll and pitch (REP-103, rad) with an honest
covariance. Calibration, impossible samples and the angle equations are those of
:class:`~accelcal_ros.sensor.tilt.TiltEstimator` (one implementation).

**Accelerometer only: averaging adapted to stillness.** The specific force ``f`` (minus the
platform acceleration when given) feeds :class:`~accelcal_ros.sensor.stillness.
StillnessDetector` (its default thresholds; with a known gyro bias a mean rate below 0.01
rad/s) and two averages:

* *fast*: a first-order low-pass ``f_fast += a (f - f_fast)``, ``a = 1 - exp(-dt /
  moving_time_constant_s)`` (0.04 s: one 25 fps frame). The output while moving is the
  double low-pass ``2 f_fast - LP(f_fast)``: no lag behind a steady turn of the sensor
  (a first-order low-pass lags by its time constant), a lag of about
  ``moving_time_constant_s`` only while the turn rate changes, and 1.6 times the
  low-pass's noise (0.08 deg at 100 Hz, 0.13 deg at 800 Hz).
* *still*: while the detector says still, the least-squares line through the samples
  since the (re)start, evaluated now, and once it spans ``still_time_constant_s`` (2 s)
  the double low-pass ``2 S - LP(S)`` of that time constant, seeded with the line's level
  and slope. Neither lags behind a slow creep the detector takes for stillness (a turn of
  2 deg/s passes its thresholds): 0.03 deg p95 at 0.5 deg/s. Noise: 0.015 deg at 100 and
  800 Hz with the datasheet noise. Cost: after a motion stops, the slope it left in the
  line decays within about twice the time constant (0.07-0.1 deg p95 in the 2 s after a
  stop). A change that the detector has not yet seen (the first 20-60 ms of a motion) is
  caught when the moving output and the still average differ by more than ``jump_sigma``
  standard deviations of the moving output on an axis (0.3-0.5 deg): the still average
  is dropped and the moving output is used for one detector window (0.3 s).

The averages' covariance and **honest when blind**: :mod:`accelcal_ros.sensor.tilt_settings`.

**Gyro-aided (complementary filter on the gravity direction).** With angular velocity ``w`` the
filter keeps ``u``, the unit "up" direction in the body frame, propagated by
``du/dt = u x (w - b)`` and pulled towards ``f / |f|`` with the gain
``k = 1 - exp(-dt / gyro_time_constant_s)`` (imu_tools' complementary filter, Mahony's proportional
term, plus his integral term on ``b``); yaw stays unobserved. Acceleration rejection per axis (x-io
Fusion rejects all axes): the innovation ``f / |f| - u``, low-passed over 0.1 s, beyond
``rejection_deg`` on body x (braking, pulling) or y (a turn's centripetal acceleration) stops the
pull on that axis only (the other is pulled towards ``f / g_scale``); in a turn (rate about up
beyond 9 deg/s, no odometry) a lever arm's centripetal acceleration reaches every axis and both
stop, unless the lever arm is known (``lever_arm_m``): the rotation's acceleration
(:mod:`~accelcal_ros.sensor.lever_arm`, from the gyro) is then removed while moving and x stays
pulled; ``| |f| - 1 |`` above ``accel_threshold_g`` stops both. The test sees an acceleration once
its low-passed innovation has grown past the limit: when an axis's rejection starts, the
corrections made on it (pull and integral term) over the last 0.5 s (``UNDO_TIME_CONSTANT_S``,
exponential weight) are undone. Rejected for ``rejection_timeout_s``, or for 3 s (1 s when odometry
says stopped) and still for 1 s with a still average within 0.003 g of 1 g in magnitude (a steady
pull is not), the accelerometer is trusted again. **Vertical aid** while rejecting
(``vertical_aid_time_constant_s``, 0: off): a vehicle accelerates horizontally, so the force along
the true up stays ``g_scale`` (1 g, learnt at rest as the mean force along ``u``); its excess along
the estimate measures the error along the horizontal acceleration
(:func:`~accelcal_ros.sensor.gyro_bias.horizontal_error`), corrected with that time constant (not
fed to the bias: the road's vibration on it would reach the bias). The gyro bias ``b`` is learnt
while the detector says still (mean corrected rate below 0.01 rad/s once a bias is known), the
accelerometer agrees within 0.5 deg and odometry, if given, says stopped; without odometry, not
from a still line whose direction turns (:func:`~accelcal_ros.sensor.tilt_settings.still_turning`:
on a smooth road a vehicle cruising over a changing grade passes the detector), and what a
stillness taught is forgotten if it turns, ends or is cut by the jump test above before its line
has shown rest: :class:`~accelcal_ros.sensor.gyro_bias.GyroBiasEstimator` (20 ms blocks a still
window has passed; a line with a drift prior ``gyro_bias_drift_rad_s2``, memory
``bias_time_constant_s``; without odometry carried over the stillness's last window). Until 0.2 s
of stillness have given a bias the output is the accelerometer-only estimate. At rest (still for
0.3 s: ``AT_REST_AFTER_S``) the direction is the Kalman update of the propagated one with each
sample, then the still average weighed by the two variances (it wins within a second).
Variance: per sample ``P = (sqrt(P + (s_w dt)^2) + s_b dt)^2`` (gyro noise ``s_w``, bias
uncertainty ``s_b`` growing by ``gyro_bias_drift_rad_s2`` per second away from stillness), then
``P = (1 - k)^2 P + k^2 R`` (``R``: the accelerometer's angle variance), plus the squared
low-passed innovation while the accelerometer is used.

Bad gyro samples (NaN, infinite, at or beyond ``gyro_saturation_rad_s``): the last good rate
for up to 0.1 s, then the accelerometer; :attr:`AttitudeFilter.gyro_rejections` counts them.
Cost: plain floats per sample (no numpy), as :class:`TiltEstimator`.
"""
import math
from typing import Dict, Optional, Sequence, Tuple

from accelcal_ros.sensor.datasheet import NOISE_STD_100HZ_G
from accelcal_ros.sensor.gyro_bias import GyroBiasEstimator, horizontal_error
from accelcal_ros.sensor.lever_arm import check_lever_arm, RotationAcceleration
from accelcal_ros.sensor.model import SensorModel
from accelcal_ros.sensor.stillness import StillnessDetector, StillnessThresholds
from accelcal_ros.sensor.tilt import AccelerationHold, TiltEstimate, TiltEstimator
from accelcal_ros.sensor.tilt_settings import (
    AT_REST_AFTER_S, BIAS_INNOVATION_LIMIT_RAD, BIAS_INTEGRAL_TIME_CONSTANT_S, BIAS_MIN_BLOCKS,
    BIAS_RATE_LIMIT_RAD_S, dema_variance_ratio, FilterSettings, G_SCALE_TIME_CONSTANT_S,
    GyroHold, holt_slope, INNOVATION_TIME_CONSTANT_S, low_pass_gain, MAX_GAP_S,
    RECOVERY_FORCE_G, RECOVERY_STILL_S, STILL_RECOVERY_S, STILL_RECOVERY_TIME_CONSTANT_S,
    STILL_RECOVERY_UNAIDED_S, still_turning, TURN_RATE_RAD_S, UNDO_TIME_CONSTANT_S,
    VERTICAL_AID_FULL_G, VERTICAL_AID_MIN_G)

MODE_ACCEL = 'accelerometer only'
MODE_BLIND = 'accelerometer only on a moving platform: tilt valid only while it does not ' \
             'accelerate'
MODE_ODOMETRY = 'accelerometer + odometry'
MODE_GYRO = 'gyro-aided'
MODE_GYRO_BAD = 'gyro samples unusable (NaN or saturated): accelerometer only'
MODE_GYRO_WAIT = 'gyro present: waiting for a still moment to learn its bias ' \
                 '(accelerometer only until then)'


class AttitudeFilter:
    """Adaptive, optionally gyro- and odometry-aided roll/pitch (see the module docstring)."""

    def __init__(self, sensor_model: Optional[SensorModel] = None,
                 noise_std_g: Sequence[float] = NOISE_STD_100HZ_G, tilt_std_rad: float = 0.0,
                 accel_threshold_g: float = 0.05, max_hold_s: float = 1.0,
                 settings: Optional[FilterSettings] = None,
                 stillness: Optional[StillnessThresholds] = None,
                 lever_arm_m: Optional[Sequence[float]] = None) -> None:
        self.tilt = TiltEstimator(sensor_model, noise_std_g, tilt_std_rad,
                                  accel_threshold_g=accel_threshold_g, max_hold_s=max_hold_s)
        self.settings = settings or FilterSettings()
        self.settings.check()
        self._stillness = stillness or StillnessThresholds(gyro_rate_rad_s=BIAS_RATE_LIMIT_RAD_S)
        self.last_rejection = ''
        """Why the last None was returned (see :class:`TiltEstimator`)."""
        self._gyro_hold = GyroHold()
        self.gyro_rejections: Dict[str, int] = self._gyro_hold.rejections
        self._arm: Optional[RotationAcceleration] = None
        if lever_arm_m is not None:
            self.set_lever_arm(lever_arm_m)
        self.jumps = 0
        """Restarts of the still average by the jump test."""
        self.reset()

    # -- configuration --------------------------------------------------------------------
    def set_settings(self, settings: FilterSettings) -> None:
        """Use new settings from now on (checked; the state is kept)."""
        settings.check()
        self.settings = settings

    def set_lever_arm(self, lever_arm_m: Optional[Sequence[float]]) -> None:
        """Set the sensor's lever arm (m, body frame; None or zeros: unknown) for the gyro path."""
        arm = None if lever_arm_m is None else check_lever_arm(lever_arm_m)
        self._arm = RotationAcceleration(arm) if arm is not None and any(arm) else None

    def set_calibration(self, sensor_model: SensorModel,
                        tilt_std_rad: Optional[float] = None) -> None:
        """Use a new calibration from now on (the filter restarts)."""
        self.tilt.set_calibration(sensor_model, tilt_std_rad)
        self.reset()

    def set_noise(self, noise_std_g: Sequence[float]) -> None:
        """Set the per-axis raw accelerometer noise (g)."""
        self.tilt.set_noise(noise_std_g)

    @property
    def calibrated(self) -> bool:
        """Return whether a calibration (not the identity) is in use."""
        return self.tilt.calibrated

    def reset(self) -> None:
        """Forget every state (averages, stillness, gyro direction; the gyro bias is kept)."""
        self.detector = StillnessDetector(self._stillness)
        self._last_t: Optional[float] = None
        self._fast: Optional[Tuple[float, float, float]] = None
        self._fast_n = 0
        self._fast2: Optional[Tuple[float, float, float]] = None
        self._still: Optional[list] = None
        self._moving_until = -math.inf
        self._hold = AccelerationHold()
        self._up: Optional[Tuple[float, float, float]] = None
        self._up_n = 0
        self._p = 0.0
        self._innovation = (0.0, 0.0, 0.0)
        self._reject_since: Optional[float] = None
        self._moved_at = -math.inf
        self._recent = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        self._rejected_x = self._rejected_y = False
        if not hasattr(self, '_g_scale'):
            self._g_scale = 1.0
            self._g_scale_n = 0
        self._gyro_hold.last = None
        if not hasattr(self, '_bias_est'):
            self._bias_est = GyroBiasEstimator(self.settings.bias_time_constant_s,
                                               self.settings.gyro_bias_drift_rad_s2)
        self._bias_est.restart()
        self.mode = MODE_ACCEL
        """Which estimate the last output is (one of the ``MODE_*`` lines)."""
        self.rejecting = False
        """Whether the gyro path ignores the accelerometer now (the platform accelerates)."""

    @property
    def bias_known(self) -> bool:
        """Return whether a gyro bias has been learnt in a still moment."""
        return self._bias_est.blocks >= BIAS_MIN_BLOCKS

    @property
    def gyro_bias_rad_s(self) -> Tuple[float, float, float]:
        """Return the gyro bias estimate (rad/s, body frame)."""
        return self._bias_est.bias

    # -- the sample -----------------------------------------------------------------------
    def update(self, stamp: float, raw_g: Sequence[float],
               gyro_rad_s: Optional[Sequence[float]] = None,
               platform_accel_g: Optional[Sequence[float]] = None,
               platform_moving: Optional[bool] = None) -> Optional[TiltEstimate]:
        """
        Return the estimate after one sample at ``stamp`` (s), or None (impossible sample).

        ``raw_g``: the raw reading (g); ``gyro_rad_s``: angular velocity of the same
        instant (body frame, rad/s) or None; ``platform_accel_g``: the platform's own
        acceleration at the sensor (body frame, g) or None; ``platform_moving``: whether
        odometry says the platform moves (None: unknown); the gyro bias is not learnt
        while it does.
        """
        tilt = self.tilt
        corrected = tilt.correct(raw_g)
        if corrected is None:
            self.last_rejection = tilt.last_rejection
            return None
        fx, fy, fz, magnitude = corrected
        settings = self.settings
        aided_by_odometry = platform_accel_g is not None
        if platform_accel_g is not None:
            fx -= platform_accel_g[0]
            fy -= platform_accel_g[1]
            fz -= platform_accel_g[2]
            magnitude = math.sqrt(fx * fx + fy * fy + fz * fz)
            if magnitude < 0.1:
                self.last_rejection = 'zero'
                return None
        last = self._last_t
        dt = 0.0
        if last is not None and stamp > last:
            dt = stamp - last
        gap = last is not None and (stamp - last > MAX_GAP_S or stamp < last)
        self._last_t = stamp if last is None or stamp > last else last
        gyro = self._gyro_hold.rate(stamp, gyro_rad_s, settings.gyro_saturation_rad_s)
        if gap:
            self._up = None
        detector = self.detector
        bias_known = self.bias_known
        self._arm_used = False
        if gyro is not None and bias_known:
            b = self._bias_est.bias
            rate = (gyro[0] - b[0], gyro[1] - b[1], gyro[2] - b[2])
            if self._arm is not None and not aided_by_odometry:
                a_rot = self._arm.update(dt, rate)
                if not detector.still:   # at rest its derivative's noise alone
                    fx, fy, fz = fx - a_rot[0], fy - a_rot[1], fz - a_rot[2]
                    magnitude = math.sqrt(fx * fx + fy * fy + fz * fz)
                    self._arm_used = True
            detector.add(stamp, (fx, fy, fz), rate)
        else:
            detector.add(stamp, (fx, fy, fz))
        still = detector.still
        self._moved_at = self._moved_at if still else stamp
        self._blind = platform_moving is None   # no odometry to tell rest from a smooth road
        if gyro is not None:   # not while the accelerometer disagrees: a steady pull
            est = self._bias_est
            est.memory_s = settings.bias_time_constant_s
            est.drift_rad_s2 = settings.gyro_bias_drift_rad_s2
            est.feed(stamp, gyro, detector.thresholds, still and not self.rejecting
                     and not platform_moving and not (self._blind and est.turning)
                     and math.hypot(*self._innovation) < BIAS_INNOVATION_LIMIT_RAD,
                     carry=not aided_by_odometry)
        # the fast and the still averages (always: the fallback and the still output)
        a_fast = low_pass_gain(dt, settings.odometry_time_constant_s if aided_by_odometry
                               else settings.moving_time_constant_s)
        fast = self._fast
        self._fast_n += 1
        if fast is None:
            fast = (fx, fy, fz)
        else:
            a = max(a_fast, 1.0 / self._fast_n)
            fast = (fast[0] + a * (fx - fast[0]), fast[1] + a * (fy - fast[1]),
                    fast[2] + a * (fz - fast[2]))
        self._fast = fast
        a2 = max(a_fast, 1.0 / self._fast_n)
        slow = self._fast2
        slow = fast if slow is None else (slow[0] + a2 * (fast[0] - slow[0]),
                                          slow[1] + a2 * (fast[1] - slow[1]),
                                          slow[2] + a2 * (fast[2] - slow[2]))
        self._fast2 = slow
        # the magnitude test on the fast average: per sample, 800 Hz noise (12 mg on z)
        # would cross 0.05 g every few seconds
        deviation = abs(math.sqrt(fast[0] ** 2 + fast[1] ** 2 + fast[2] ** 2) - 1.0)
        accelerating = deviation > tilt.accel_threshold_g
        # uncalibrated, |f| reads 0.85-1.15 g at rest: the magnitude proves nothing
        blocks = accelerating and tilt.calibrated
        a_eff = max(a_fast, 1.0 / self._fast_n) if self._fast_n > 1 else 1.0
        # moving: 2 EMA - EMA(EMA), no lag behind a steady turn of the sensor
        out = (2.0 * fast[0] - slow[0], 2.0 * fast[1] - slow[1], 2.0 * fast[2] - slow[2])
        shrink = dema_variance_ratio(a_eff)
        if still and not blocks and stamp >= self._moving_until:
            out, shrink = self._still_average(fast, out, (fx, fy, fz), stamp, dt, shrink)
        else:
            if self._still is not None and self._blind:
                self._bias_est.still_ended()
            self._still = None
        if gyro is not None and bias_known:
            return self._gyro_update(stamp, dt, gyro, (fx, fy, fz), magnitude, accelerating,
                                     aided_by_odometry, out, shrink, platform_moving,
                                     still and self._still is not None)
        self._up = None   # starts from the still average once the bias is known
        mode = None
        if gyro is not None:
            mode = MODE_GYRO_WAIT
        elif gyro_rad_s is not None:
            mode = MODE_GYRO_BAD
        return self._accel_output(stamp, (fx, fy, fz), magnitude, deviation, accelerating,
                                  still, out, shrink, aided_by_odometry, mode)

    # -- pieces ---------------------------------------------------------------------------
    def _still_average(self, fast, dema, force, stamp, dt, shrink_dema):
        """
        Return (average, variance ratio) while still, restarting on a jump.

        From a (re)start the average is the least-squares line through the samples so far,
        evaluated now; once that spans ``still_time_constant_s`` it goes on as the double
        low-pass ``2 S - LP(S)`` of that time constant, seeded with the line's level and
        slope. Neither lags behind a slow creep that the detector takes for stillness.
        """
        state = self._still
        cov = self.tilt.force_covariance_list_g2
        if state is not None:
            limit = self.settings.jump_sigma
            out = state[0]
            for k, var in enumerate((cov[0], cov[4], cov[8])):
                if abs(dema[k] - out[k]) > limit * math.sqrt(var * shrink_dema) + 5e-4:
                    # a motion the detector has not seen yet: moving for one window
                    self.jumps += 1
                    if self._blind:   # motion after all: unless shown at rest, no bias
                        self._bias_est.still_ended()
                    self._still = None
                    self._moving_until = stamp + self.detector.thresholds.window_s
                    return dema, shrink_dema
        if state is None:
            # sums of the regression: n, t, t^2, then per axis y and t*y (t from now)
            state = self._still = [dema, 'line', stamp, [0.0, 0.0, 0.0],
                                   [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]]
            self._bias_est.still_started(self._moved_at)
        a = low_pass_gain(dt, self.settings.still_time_constant_s)
        fx, fy, fz = force
        if state[1] == 'line':
            sums = state[4]
            t = stamp - state[2]
            sums[0] += 1.0
            sums[1] += t
            sums[2] += t * t
            sums[3] += fx
            sums[4] += fy
            sums[5] += fz
            n = sums[0]
            ty = state[3]
            ty[0] += t * fx
            ty[1] += t * fy
            ty[2] += t * fz
            den = n * sums[2] - sums[1] * sums[1]
            shrink = (4.0 * n - 2.0) / (n * (n + 1.0))
            if n < 8 or den <= 1e-18 or shrink >= shrink_dema:   # the moving one is better
                return dema, shrink_dema
            mean_t = sums[1] / n
            level, slope = [], []
            for k in range(3):
                m = (n * ty[k] - sums[1] * sums[3 + k]) / den
                slope.append(m)
                level.append(sums[3 + k] / n + m * (t - mean_t))
            out = (level[0], level[1], level[2])
            state[0] = out
            if self._blind and stamp >= self._bias_est.rest_due:   # per 20 ms block
                self._rest(stamp, still_turning(level, slope, n / den, cov))
            if a > 0.0 and 1.0 / n < a:   # the line spans the time constant: go on as 2S - S2
                d = [m * dt * (1.0 - a) / a for m in slope]
                state[1] = 'holt'
                state[3] = [level[k] - d[k] for k in range(3)]
                state[4] = [level[k] - 2.0 * d[k] for k in range(3)]
            return out, shrink
        s1, s2 = state[3], state[4]
        for k, y in enumerate((fx, fy, fz)):
            s1[k] += a * (y - s1[k])
            s2[k] += a * (s1[k] - s2[k])
        out = (2.0 * s1[0] - s2[0], 2.0 * s1[1] - s2[1], 2.0 * s1[2] - s2[2])
        state[0] = out
        if self._blind and stamp >= self._bias_est.rest_due and 0.0 < a < 1.0:
            self._rest(stamp, still_turning(out, *holt_slope(s1, s2, a, dt), cov))
        return out, dema_variance_ratio(a)

    def _rest(self, stamp, verdict):
        self._bias_est.rest(stamp + self.detector.thresholds.block_s, verdict)

    def _accel_output(self, stamp, force, magnitude, deviation, accelerating, still, out,
                      shrink, aided_by_odometry, mode):
        tilt = self.tilt
        settings = self.settings
        held = self._hold.estimate(stamp, accelerating, tilt.calibrated, tilt.max_hold_s,
                                   force, magnitude, deviation)
        if held is not None:
            self.mode = mode or MODE_ACCEL
            return held
        roll, pitch, (c00, c01, c11) = tilt.angles_with_covariance(out[0], out[1], out[2],
                                                                   shrink)
        good = (roll, pitch, (c00, c01, c11))
        extra = 0.0
        if aided_by_odometry:
            extra = settings.odometry_accel_std_g ** 2
            self.mode = mode or MODE_ODOMETRY
        else:
            if not still:
                spread = self.detector.motion_std
                spread = spread if math.isfinite(spread) else 0.0
                extra = max(math.asin(min(1.0, deviation)), math.atan(spread)) ** 2
            if settings.platform_accel_g > 0.0:
                extra += math.atan(settings.platform_accel_g) ** 2
                self.mode = mode or MODE_BLIND
            else:
                self.mode = mode or MODE_ACCEL
        if accelerating:
            extra = max(extra, math.asin(min(1.0, deviation)) ** 2)
        elif tilt.calibrated:
            self._hold.held = good
        self.rejecting = False
        return TiltEstimate(stamp, roll, pitch, force, (c00 + extra, c01, c11 + extra),
                            accelerating, magnitude)

    def _undo_onset(self, new_x, new_y, both, vx, vy, vz):
        """Take back the recent corrections on the axes whose rejection starts now."""
        r, b, v = self._recent, list(self._bias_est.bias), [vx, vy, vz]
        # body x (pitch) is corrected through the bias about y, body y (roll) about x
        for on, k, j in ((new_x, 0, 4), (new_y, 1, 3), (both, 2, 5)):
            if on:
                v[k] -= r[k]
                b[j - 3] -= r[j]
                r[k] = r[j] = 0.0
        self._bias_est.adjust((b[0], b[1], b[2]))
        return v[0], v[1], v[2]

    def _gyro_update(self, stamp, dt, gyro, force, magnitude, accelerating,
                     aided_by_odometry, out, shrink, platform_moving, still):
        """Run the complementary filter on the up direction; return its estimate."""
        settings = self.settings
        fx, fy, fz = force
        inv = 1.0 / magnitude
        ux, uy, uz = fx * inv, fy * inv, fz * inv
        cov = self.tilt.force_covariance_list_g2
        r_var = (cov[0] + cov[4] + cov[8]) / 3.0
        if aided_by_odometry:   # what the odometry's acceleration may be off by
            r_var += settings.odometry_accel_std_g ** 2
        up = self._up
        if up is None:   # (re)start from the accelerometer's current average
            sx, sy, sz = out
            norm = math.sqrt(sx * sx + sy * sy + sz * sz)
            self._up = (sx / norm, sy / norm, sz / norm)
            self._up_n = 1
            self._p = r_var * shrink
            self._innovation = (0.0, 0.0, 0.0)
            self._reject_since = None
            self._recent = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
            self._rejected_x = self._rejected_y = False
        else:
            b = self._bias_est.bias
            wx, wy, wz = gyro[0] - b[0], gyro[1] - b[1], gyro[2] - b[2]
            vx, vy, vz = up
            vx, vy, vz = (vx + dt * (vy * wz - vz * wy), vy + dt * (vz * wx - vx * wz),
                          vz + dt * (vx * wy - vy * wx))
            propagated = (vx, vy, vz)
            ex, ey, ez = ux - vx, uy - vy, uz - vz
            a_inn = low_pass_gain(dt, INNOVATION_TIME_CONSTANT_S)
            ix, iy, iz = self._innovation
            ix, iy, iz = ix + a_inn * (ex - ix), iy + a_inn * (ey - iy), iz + a_inn * (ez - iz)
            self._innovation = (ix, iy, iz)
            limit = math.radians(settings.rejection_deg)
            # per axis: a turn's centripetal acceleration lies along body y (roll), braking
            # and pulling along body x (pitch); the other axis still sees gravity alone
            # turning (rate about up): the lever arm's centripetal acceleration reaches
            # both axes; a straight pull or braking leaves body y (roll) to gravity
            turning = not aided_by_odometry and abs(wx * vx + wy * vy + wz * vz) > TURN_RATE_RAD_S
            reject_x = (turning and not self._arm_used) or abs(ix) > limit
            reject_y = turning or abs(iy) > limit
            reject = (accelerating and self.tilt.calibrated) or (reject_x and reject_y)
            k_fast = 0.0
            if reject or reject_x or reject_y:
                since = self._reject_since
                if since is None:
                    self._reject_since = since = stamp
                still_for = STILL_RECOVERY_S if platform_moving is False \
                    else STILL_RECOVERY_UNAIDED_S
                if stamp - since > settings.rejection_timeout_s or (
                        stamp - since > still_for and stamp - self._moved_at >= RECOVERY_STILL_S
                        and abs(math.hypot(*out) - self._g_scale) < RECOVERY_FORCE_G):
                    # trusted again: fast while still (stopped after a drift)
                    reject = reject_x = reject_y = False
                    k_fast = low_pass_gain(dt, STILL_RECOVERY_TIME_CONSTANT_S) \
                        if self.detector.still else 0.0
            else:
                self._reject_since = None
            rx, ry = reject or reject_x, reject or reject_y
            if (rx and not self._rejected_x) or (ry and not self._rejected_y):
                vx, vy, vz = self._undo_onset(rx and not self._rejected_x,
                                              ry and not self._rejected_y, rx and ry,
                                              vx, vy, vz)
            self._rejected_x = rx
            self._rejected_y = ry
            self._up_n += 1
            k = 0.0 if reject else max(low_pass_gain(dt, settings.gyro_time_constant_s), k_fast,
                                       1.0 / self._up_n if self._up_n < 100 else 0.0)
            kx = 0.0 if reject_x else k
            ky = 0.0 if reject_y else k
            if kx != ky:
                # one axis rejected: the trusted one against the specific force over the
                # magnitude at rest (|f| grows with the rejected axis's acceleration)
                scale = 1.0 / self._g_scale
                ex, ey = fx * scale - vx, fy * scale - vy
            elif k > 0.0 and still:
                self._g_scale_n += 1
                # the force along "up", not |f|: the noise across it biases |f| upwards
                # (by 0.0004 g at 800 Hz)
                self._g_scale += max(1.0 / self._g_scale_n,
                                     low_pass_gain(dt, G_SCALE_TIME_CONSTANT_S)) * (
                    fx * vx + fy * vy + fz * vz - self._g_scale)
            if k > 0.0 and not still and self._up_n >= 100:
                # Mahony's integral term: a steady innovation is a bias error
                ki = dt / (BIAS_INTEGRAL_TIME_CONSTANT_S * settings.gyro_time_constant_s)
                jx = 0.0 if reject_x else ix
                jy = 0.0 if reject_y else iy
                jz = iz if kx == ky else 0.0
                cx, cy, cz = jy * vz - jz * vy, jz * vx - jx * vz, jx * vy - jy * vx
                b = self._bias_est.bias
                self._bias_est.adjust((b[0] - ki * cx, b[1] - ki * cy, b[2] - ki * cz))
                r = self._recent
                r[3] -= ki * cx
                r[4] -= ki * cy
                r[5] -= ki * cz
            if kx == ky:
                dx, dy, dz = k * ex, k * ey, k * ez
            else:
                dx, dy, dz = kx * ex, ky * ey, 0.0
            vx, vy, vz = vx + dx, vy + dy, vz + dz
            k = min(kx, ky)
            reject = reject or reject_x or reject_y
            if reject and settings.vertical_aid_time_constant_s > 0.0:
                found = horizontal_error(fx, fy, fz, vx, vy, vz, self._g_scale,
                                         VERTICAL_AID_MIN_G, VERTICAL_AID_FULL_G)
                if found is not None:   # v corrected along the horizontal acceleration
                    ka = low_pass_gain(dt, settings.vertical_aid_time_constant_s) * found[3]
                    vx, vy, vz = vx + ka * found[0], vy + ka * found[1], vz + ka * found[2]
            est = self._bias_est
            drift = settings.gyro_bias_drift_rad_s2 * max(0.0, stamp - est.time)
            s_b = math.sqrt(est.variance) + drift
            if still and not reject and stamp - self._moved_at >= AT_REST_AFTER_S:
                # at rest the accelerometer is unbiased: a Kalman gain on the propagated
                # direction (a growing average that the gyro keeps aligned), then the
                # still average once its variance is the smaller (its line through the
                # few samples just after a stop is not)
                vx, vy, vz = propagated
                s = math.sqrt(self._p + (settings.gyro_noise_std_rad_s * dt) ** 2) + s_b * dt
                p_pred = s * s
                kk = p_pred / (p_pred + r_var) if p_pred + r_var > 0.0 else 1.0
                vx, vy, vz = vx + kk * (ux - vx), vy + kk * (uy - vy), vz + kk * (uz - vz)
                p_now = (1.0 - kk) * p_pred
                r_still = r_var * shrink
                kb = p_now / (p_now + r_still) if p_now + r_still > 0.0 else 1.0
                sx, sy, sz = out
                inv = 1.0 / math.sqrt(sx * sx + sy * sy + sz * sz)
                vx, vy, vz = (vx + kb * (sx * inv - vx), vy + kb * (sy * inv - vy),
                              vz + kb * (sz * inv - vz))
                self._p = (1.0 - kb) * p_now
                k = 1.0
                self._recent = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]   # at rest: nothing to take back
            else:
                # the corrections of the last UNDO_TIME_CONSTANT_S (the vertical aid's aside)
                r = self._recent
                keep = max(0.0, 1.0 - dt / UNDO_TIME_CONSTANT_S)   # exp(-dt / tau), dt << tau
                r[0] = r[0] * keep + dx
                r[1] = r[1] * keep + dy
                r[2] = r[2] * keep + dz
                r[3] *= keep
                r[4] *= keep
                r[5] *= keep
            norm = math.sqrt(vx * vx + vy * vy + vz * vz)
            self._up = (vx / norm, vy / norm, vz / norm)
            if k < 1.0:
                s = math.sqrt(self._p + (settings.gyro_noise_std_rad_s * dt) ** 2) + s_b * dt
                self._p = (1.0 - k) ** 2 * s * s + k * k * r_var
            self.rejecting = reject
        vx, vy, vz = self._up
        roll = math.atan2(vy, vz)
        pitch = math.atan2(-vx, math.hypot(vy, vz))
        extra = self.tilt.tilt_std_rad ** 2
        if not self.rejecting:
            ix, iy, iz = self._innovation
            extra += ix * ix + iy * iy + iz * iz
        variance = self._p + extra
        self.mode = MODE_GYRO if not aided_by_odometry else f'{MODE_GYRO} + odometry'
        return TiltEstimate(stamp, roll, pitch, force, (variance, 0.0, variance),
                            accelerating or self.rejecting, magnitude)
