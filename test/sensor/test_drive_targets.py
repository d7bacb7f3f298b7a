"""Issue 20's targets through the simulated drive, on several seeds and at 100 and 800 Hz.

Spread at 100 / 800 Hz (README "Attitude at rest and in motion"): gyro (with the drive's
lever arm), seeds 0-31, p95 0.13-0.37 / 0.15-0.28 deg, max <= 0.50; seeds 0-7, odometry
p95 0.35-0.41, max <= 0.91; both p95 0.11-0.26, max <= 0.33.
"""
from dataclasses import replace
import math

from accelcal_ros.attitude.study import _package, score
from accelcal_ros.sensor.drive_sim import DRIVE_SEGMENTS, simulate_drive
from accelcal_ros.sensor.gyro_bias import GyroBiasEstimator, horizontal_error
from accelcal_ros.sensor.tilt_settings import holt_slope, still_turning
import numpy as np
import pytest

TARGET_MAX_DEG = 1.0
"""With a gyro: no error beyond 1 deg through the 0.3 g manoeuvres (issue 20)."""
TARGET_ODOMETRY_P95_DEG = 1.0
"""Odometry only: p95 <= 1 deg (issue 20)."""
TARGET_GYRO_P95_DEG = 0.3
"""With a gyro: p95 <= 0.3 deg (issue 20); met by gyro + odometry and, with the drive's
lever arm known, by the gyro alone on the seeds below (p95 0.16-0.25 deg) and on most
others (the README gives the spread). Seed 30 (0.25 / 0.20 deg at 100 / 800 Hz): its pull
away passed the stillness detector for one block 3 s into the rejection, and the
accelerometer, trusted again, faked 7.5 deg (p95 15 / 8.6 deg before the recovery needed
1 s of stillness at 1 g)."""
BOTH_OVER_GYRO_DEG = 0.03
"""Both aids against the gyro alone that does not know the lever arm (so turns stop the
accelerometer on both axes): odometry adds its noise, and on a few seeds that gyro alone
is the better (drive seeds 0-31: 2 at 100 Hz, 3 at 800 Hz; 100 Hz seed 1: 0.278 against
0.262 deg). With the lever arm the gyro alone is better than both aids on 100 Hz seeds 1
and 11 (0.17 / 0.18 against 0.28 / 0.26 deg): in turns the odometry-corrected
accelerometer pulls roll, the gyro alone holds it."""


@pytest.mark.parametrize('rate, seed', [(100.0, 0), (100.0, 1), (100.0, 2), (800.0, 0),
                                        (800.0, 3), (100.0, 30), (800.0, 30)])
def test_drive_targets_per_aid(rate, seed):
    drive = simulate_drive(rate_hz=rate, seed=seed)
    # the drive holds what the targets speak of: 0.3 g turns and braking, a stop
    assert max(abs(s[3]) for s in DRIVE_SEGMENTS) == 0.3
    assert min(s[2] for s in DRIVE_SEGMENTS) == -0.3
    gyro = score(drive, *_package(drive, True, False))
    unknown_arm = score(drive, *_package(replace(drive, lever_arm_m=(0.0, 0.0, 0.0)), True,
                                         False))
    odo = score(drive, *_package(drive, False, True))
    both = score(drive, *_package(drive, True, True))
    accel = score(drive, *_package(drive, False, False))
    # the test can fail: unaided, a 0.3 g turn fakes 16.7 deg of tilt
    assert accel['p95_deg'] > 10.0
    assert gyro['max_deg'] <= TARGET_MAX_DEG
    assert both['max_deg'] <= TARGET_MAX_DEG
    assert odo['p95_deg'] <= TARGET_ODOMETRY_P95_DEG / 2.0   # the target with a margin
    assert odo['max_deg'] <= TARGET_MAX_DEG
    # both aids: the gyro target, and about as good as the gyro alone or better
    assert both['p95_deg'] <= TARGET_GYRO_P95_DEG
    assert both['p95_deg'] <= unknown_arm['p95_deg'] + BOTH_OVER_GYRO_DEG
    # the gyro alone with the lever arm: the target on these seeds (the spread: README)
    assert gyro['p95_deg'] <= TARGET_GYRO_P95_DEG
    assert unknown_arm['max_deg'] <= TARGET_MAX_DEG


SMOOTH_ROAD_P95_DEG = 0.5
"""The gyro alone on a perfectly smooth road (``vibration_g=0``), 100 Hz seed 0: p95 0.19
deg (0.48 before the at-rest update waited for 0.3 s of stillness); 2.34 deg when a
vehicle cruising over the changing grade, still to the detector, taught the gyro bias its
rate."""


def test_smooth_road_grade_is_not_learnt_as_gyro_bias():
    drive = simulate_drive(rate_hz=100.0, seed=0, vibration_g=0.0)
    gyro = score(drive, *_package(drive, True, False))
    assert gyro['p95_deg'] <= SMOOTH_ROAD_P95_DEG


LOW_VIBRATION_P95_DEG = 0.5
"""The gyro alone on a road with little vibration (``vibration_g`` 0.01 g), 100 Hz seed 3
and 800 Hz seed 1: p95 0.26 / 0.18 deg. It was 3.2 / 4.4 deg while a cruise that the
detector took for stillness, cut short by the still average's jump test, kept what it
taught the gyro bias (the rate over the changing grade: 0.5 deg/s)."""


@pytest.mark.parametrize('rate, seed', [(100.0, 3), (800.0, 1)])
def test_a_cruise_cut_by_the_jump_test_teaches_no_gyro_bias(rate, seed):
    drive = simulate_drive(rate_hz=rate, seed=seed, vibration_g=0.01)
    gyro = score(drive, *_package(drive, True, False))
    assert gyro['p95_deg'] <= LOW_VIBRATION_P95_DEG
    assert gyro['max_deg'] <= 2.0 * LOW_VIBRATION_P95_DEG


AT_REST_SNAP_MAX_DEG = 0.6
"""The gyro alone on smooth roads where a cruise or a braking's onset passed the stillness
detector for a block or two and the at-rest update snapped to the acceleration before it
waited :data:`~accelcal_ros.sensor.tilt_settings.AT_REST_AFTER_S`: 100 Hz seed 2 and
800 Hz seed 0 at ``vibration_g`` 0 (p95 / max 1.16 / 1.51 and 1.37 / 1.64 deg, now
0.19 / 0.29 and 0.15 / 0.20), 800 Hz seed 4 at 0.01 g (0.47 / 0.54 before the lever arm,
0.45 / 1.10 with it and no wait, now 0.32 / 0.37)."""


@pytest.mark.parametrize('rate, seed, vibration', [(100.0, 2, 0.0), (800.0, 0, 0.0),
                                                   (800.0, 4, 0.01)])
def test_a_moment_of_stillness_while_driving_does_not_snap_to_the_accelerometer(
        rate, seed, vibration):
    drive = simulate_drive(rate_hz=rate, seed=seed, vibration_g=vibration)
    gyro = score(drive, *_package(drive, True, False))
    assert gyro['max_deg'] <= AT_REST_SNAP_MAX_DEG
    assert gyro['p95_deg'] <= 0.4


def test_still_turning_tells_a_turning_line_from_rest():
    var = 0.003 ** 2
    cov = [var, 0.0, 0.0, 0.0, var, 0.0, 0.0, 0.0, var]
    ratio = 12.0 / (200 * 2.0 ** 2)   # a line through 200 samples over 2 s
    level = (0.0, 0.0, 1.0)
    # at rest: shown at rest; 0.4 deg/s of pitch rate (a grade): turning
    assert still_turning(level, (0.0, 0.0, 0.0), ratio, cov) == (False, True)
    assert still_turning(level, (math.radians(0.4), 0.0, 0.0), ratio, cov) == (True, False)
    # along the direction (|f| changing) is no rotation; too noisy a line shows nothing
    assert still_turning(level, (0.0, 0.0, 0.01), ratio, cov) == (False, True)
    assert still_turning(level, (0.0, 0.0, 0.0), ratio * 100.0, cov) == (False, False)
    # the double low-pass's slope: a ramp of 0.01 g/s read back
    a, dt = 0.005, 0.01
    lag = 0.01 * dt * (1.0 - a) / a
    slope, ratio2 = holt_slope((0.0, 0.0, lag), (0.0, 0.0, 0.0), a, dt)
    assert slope[2] == pytest.approx(0.01) and 0.0 < ratio2 < ratio


def test_gyro_bias_constant_is_averaged_and_drift_is_followed():
    rng = np.random.default_rng(5)
    rate, sigma = 100.0, math.radians(0.38)
    t = np.arange(0.0, 5.0, 1.0 / rate)
    errors_constant, errors_drift = [], []
    for trial in range(20):
        for drift, errors in ((0.0, errors_constant), (math.radians(0.04), errors_drift)):
            est = GyroBiasEstimator(memory_s=30.0, drift_rad_s2=math.radians(0.04))
            bias = 0.01 + drift * t
            rates = bias[:, None] + rng.standard_normal((t.size, 3)) * sigma
            for k in range(0, t.size, 2):   # 20 ms blocks
                est.add(t[k], t[k + 1], tuple(rates[k:k + 2].mean(axis=0)), 2)
            errors.append(est.bias[0] - bias[-1])
            # the stated variance is the scatter's (within a factor of 3)
            assert math.sqrt(est.variance) < 3.0 * 2.0 * sigma / math.sqrt(t.size)
    mean_lag = math.radians(0.04) * 5.0 / 2.0
    rms_c = math.sqrt(np.mean(np.square(errors_constant)))
    rms_d = math.sqrt(np.mean(np.square(errors_drift)))
    # constant: near the line end's precision (2 sigma / sqrt(N)), far below a drift's lag
    assert rms_c < 2.5 * 2.0 * sigma / math.sqrt(t.size)
    # drifting: a mean would lag by slope * T / 2 (0.1 deg/s); the line follows
    assert rms_d < mean_lag / 2.0
    assert abs(np.mean(errors_drift)) < mean_lag / 4.0


def test_gyro_bias_line_goes_on_over_a_short_gap_of_the_same_stillness():
    """
    Go on with the bias line over the blocks the caller left out.

    Odometry's speed noise reads 'moving' for a sample at a stop: a restart kept the old
    level as its prior and lagged behind the drift (0.07 deg/s at the end of the drive's
    stop, seed 5 at 800 Hz); a new stillness
    (:meth:`GyroBiasEstimator.still_started`) still starts a new line.
    """
    rng = np.random.default_rng(2)
    rate, sigma, drift = 800.0, math.radians(0.5), math.radians(0.04)
    t = np.arange(0.0, 4.0, 1.0 / rate)
    gaps, step = (1.2, 1.8), 16   # two gaps of 0.3 s; 20 ms blocks
    lag: dict = {True: [], False: []}
    for trial in range(10):
        rates = 0.01 + drift * t[:, None] + rng.standard_normal((t.size, 3)) * sigma
        for same_stillness in (True, False):
            est = GyroBiasEstimator(memory_s=30.0, drift_rad_s2=drift)
            est.still_started(-1.0)
            started = set()
            for k in range(0, t.size - step + 1, step):
                if any(0.0 <= t[k] - g < 0.3 for g in gaps):
                    continue
                after = [g for g in gaps if t[k] >= g + 0.3]
                if not same_stillness and after and after[-1] not in started:
                    started.add(after[-1])
                    est.still_started(float(t[k]))
                est.add(t[k], t[k + step - 1], tuple(rates[k:k + step].mean(axis=0)), step)
            lag[same_stillness].append(est.bias[0] - (0.01 + drift * t[-1]))
    joined, restarted = np.array(lag[True]), np.array(lag[False])
    # one line through the gaps: its end's precision (2 sigma / sqrt(N)), no lag
    precision = 2.0 * sigma / math.sqrt(0.85 * t.size)
    assert math.sqrt(np.mean(joined ** 2)) < 2.5 * precision
    assert abs(np.mean(joined)) < precision
    # new lines: each starts from the old level, which holds it back
    assert np.mean(restarted) < -3.0 * precision


@pytest.mark.parametrize('a_g', [0.1, 0.3])
def test_horizontal_error_measures_the_error_along_the_acceleration(a_g):
    up = np.array([math.sin(0.03), -math.sin(0.02), 1.0])
    up /= np.linalg.norm(up)
    side = np.cross(up, [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    force = up + a_g * side   # horizontal acceleration: the force along up stays 1 g
    err = np.radians(0.5) * side + np.radians(0.3) * np.cross(up, side)
    estimate = (up - err) / np.linalg.norm(up - err)
    ex, ey, ez, weight = horizontal_error(*force, *estimate, 1.0, 0.03, 0.2)
    found = np.array([ex, ey, ez])
    # the error along the acceleration; across it nothing but second order terms
    # (about along * across / a)
    along, across = math.radians(0.5), math.radians(0.3)
    assert float(found @ side) == pytest.approx(along, rel=0.05)
    assert abs(float(found @ np.cross(up, side))) < 2.0 * along * across / a_g
    # the weight: (|h| / 0.2 g)^2, |h| measured across the estimate (a +- its error)
    error = math.hypot(along, across)
    assert min(1.0, ((a_g - error) / 0.2) ** 2) <= weight <= min(1.0, ((a_g + error) / 0.2) ** 2)
    assert horizontal_error(*up, *estimate, 1.0, 0.03, 0.2) is None   # no acceleration
