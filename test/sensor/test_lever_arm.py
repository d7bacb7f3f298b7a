"""The rotation's acceleration at a lever arm (sensor/lever_arm.py), used by the gyro path."""
import math

from accelcal_ros.errors import InputError
from accelcal_ros.sensor.lever_arm import (check_lever_arm, RATE_TIME_CONSTANT_S,
                                           rotation_accel, RotationAcceleration)
from accelcal_ros.sensor.odometry_aid import accel_series_g
from accelcal_ros.sensor.tilt_filter import AttitudeFilter
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
import numpy as np
import pytest

G = STANDARD_GRAVITY_M_S2


def test_rotation_accel_is_the_rigid_body_formula_for_floats_and_arrays():
    rng = np.random.default_rng(4)
    w, w_dot, p = rng.normal(size=(3, 50, 3))
    expected = np.cross(w_dot, p) + np.cross(w, np.cross(w, p))
    got = np.stack(rotation_accel(w.T, w_dot.T, p.T), axis=1)
    np.testing.assert_allclose(got, expected, atol=1e-12)
    one = rotation_accel(tuple(w[0]), tuple(w_dot[0]), tuple(p[0]))
    assert all(isinstance(v, float) for v in one)
    np.testing.assert_allclose(one, expected[0], atol=1e-12)


def test_odometry_uses_the_same_formula_about_up():
    # yaw rate 0.2 rad/s rising by 0.1 rad/s^2, sensor at (1, 0.5, 0.8): the rotation's
    # part of the odometry's acceleration is rotation_accel about z (the speed is 0)
    t = np.arange(0.0, 4.0, 0.02)
    arm = (1.0, 0.5, 0.8)
    acc = accel_series_g([2.0], t, np.zeros(t.size), 0.2 + 0.1 * (t - 2.0), arm)[0]
    expected = np.array(rotation_accel((0.0, 0.0, 0.2), (0.0, 0.0, 0.1), arm)) / G
    np.testing.assert_allclose(acc, expected, atol=1e-9)


@pytest.mark.parametrize('bad', [(1.0, 2.0), (1.0, math.nan, 0.0), ('a', 0, 0), None,
                                 (0.0, math.inf, 0.0)])
def test_a_bad_lever_arm_is_refused_with_the_reason(bad):
    with pytest.raises(InputError, match='lever_arm_m must be 3 finite numbers'):
        check_lever_arm(bad)
    if bad is not None:   # None is an unknown lever arm for the filter
        with pytest.raises(InputError, match='lever_arm_m must be 3 finite numbers'):
            AttitudeFilter(lever_arm_m=bad)


def test_live_estimate_follows_a_steady_turn_and_the_turn_onset():
    arm = (1.0, 0.3, 0.8)
    est = RotationAcceleration(arm)
    dt = 0.01
    t = np.arange(0.0, 6.0, dt)
    # the yaw rate ramps from 0 to 0.33 rad/s over 1 s from t = 1 s, then holds
    r = 0.33 * np.clip(t - 1.0, 0.0, 1.0)
    out = np.array([est.update(dt, (0.0, 0.0, ri)) for ri in r])
    steady = np.array(rotation_accel((0.0, 0.0, 0.33), (0.0, 0.0, 0.0), arm)) / G
    np.testing.assert_allclose(out[-1], steady, atol=1e-6)
    # mid-ramp the tangential part is there, lagging by about two time constants
    k = int(round((1.5 + 2 * RATE_TIME_CONSTANT_S) / dt))
    ramp = np.array(rotation_accel((0.0, 0.0, r[k] - 2 * RATE_TIME_CONSTANT_S * 0.33),
                                   (0.0, 0.0, 0.33), arm)) / G
    np.testing.assert_allclose(out[k], ramp, atol=0.002)


def test_the_road_s_vibration_on_the_gyro_stays_a_few_mg():
    # 0.5 deg/s at 8-25 Hz about every axis (the drive simulator's road): its derivative
    # is 0.9 rad/s^2, 0.1 g at 1.3 m; the two low-passes keep a few mg of it
    est = RotationAcceleration((1.0, 0.3, 0.8))
    dt = 0.01
    t = np.arange(0.0, 10.0, dt)
    rng = np.random.default_rng(1)
    w = sum(np.sin(2 * np.pi * f * t[:, None] + rng.uniform(0, 6.3, 3))
            for f in (8.0, 13.0, 19.0, 25.0)) * math.radians(0.5) / math.sqrt(2.0)
    out = np.array([est.update(dt, tuple(wi)) for wi in w])[100:]
    assert np.sqrt((out ** 2).mean(axis=0)).max() < 0.005


def test_a_filter_without_a_lever_arm_or_with_zeros_leaves_the_force_alone():
    assert AttitudeFilter()._arm is None
    assert AttitudeFilter(lever_arm_m=(0.0, 0.0, 0.0))._arm is None
    f = AttitudeFilter(lever_arm_m=(1.0, 0.0, 0.0))
    assert f._arm is not None
    f.set_lever_arm(None)
    assert f._arm is None


def _turn_run(drive, arm):
    """Return per sample of a drive: rejected on body x, pitch error (deg)."""
    from accelcal_ros.sensor.datasheet import datasheet_noise_std_g

    f = AttitudeFilter(noise_std_g=tuple(datasheet_noise_std_g(drive.rate_hz).tolist()),
                       lever_arm_m=arm)
    rejected, error = [], []
    for k in range(drive.t.size):
        e = f.update(float(drive.t[k]), drive.accel_g[k], drive.gyro_rad_s[k])
        rejected.append(f.rejecting and f._rejected_x)
        error.append(math.degrees(e.pitch - drive.pitch[k]))
    return np.array(rejected), np.array(error)


def test_a_known_lever_arm_leaves_pitch_to_the_accelerometer_in_a_steady_turn():
    from accelcal_ros.sensor.drive_sim import DRIVE_SEGMENTS, simulate_drive

    drive = simulate_drive(100.0, seed=9)
    ends = np.cumsum([s[1] for s in DRIVE_SEGMENTS])
    k = [i for i, s in enumerate(DRIVE_SEGMENTS) if s[0] == 'turn 0.3 g'][0]
    steady = (drive.t > ends[k] - DRIVE_SEGMENTS[k][1] + 1.5) & (drive.t < ends[k] - 0.5)
    blind_x, blind_err = _turn_run(drive, None)
    known_x, known_err = _turn_run(drive, drive.lever_arm_m)
    # unknown: the lever arm's centripetal 0.011 g could be on x, so x is not trusted
    assert blind_x[steady].mean() > 0.95
    assert known_x[steady].mean() < 0.05
    # and pitch follows the accelerometer there (seed 9: p95 0.13 -> 0.09 deg)
    p95 = [np.percentile(np.abs(err[steady]), 95) for err in (blind_err, known_err)]
    assert p95[1] < p95[0]
    print(f'pitch error in the steady 0.3 g turn, p95: unknown lever arm '
          f'{np.percentile(np.abs(blind_err[steady]), 95):.3f} deg, known '
          f'{np.percentile(np.abs(known_err[steady]), 95):.3f} deg')
