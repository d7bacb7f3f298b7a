"""The attitude filter: steady at rest, right in motion, honest when blind, bad input."""
import math

from accelcal_ros.driver.sim_sensor import SimulatedAdxl345
from accelcal_ros.errors import AccelcalError, InputError
from accelcal_ros.frames import specific_force_from_roll_pitch
from accelcal_ros.sensor import tilt_filter
from accelcal_ros.sensor.datasheet import datasheet_noise_std_g
from accelcal_ros.sensor.drive_sim import simulate_drive
from accelcal_ros.sensor.model import SensorModel
from accelcal_ros.sensor.odometry_aid import accel_series_g, OdometryAid
from accelcal_ros.sensor.tilt import TiltEstimator
from accelcal_ros.sensor.tilt_filter import (AttitudeFilter, FilterSettings, MODE_BLIND,
                                             MODE_GYRO, MODE_GYRO_BAD)
from accelcal_ros.sensor.tilt_series import estimate_series, read_odometry_csv
import numpy as np
import pytest

FOCAL_PX = 1100.0
FRAME_S = 0.04   # 25 fps


def _still(rate, seconds=20.0, seed=3):
    sim = SimulatedAdxl345(rate_hz=rate, poses_deg=[[4.0, -7.0]], dwell_s=1e4, move_s=0.0,
                           seed=seed)
    t = np.arange(0.0, seconds, 1.0 / rate)
    raw, roll, pitch = sim.read_with_truth(t)
    return sim, t, raw, roll, pitch


def _run(filt, t, raw, gyro=None):
    gyro = [None] * len(t) if gyro is None else gyro.tolist()
    return [filt.update(ti, ai, gi) for ti, ai, gi in zip(t.tolist(), raw.tolist(), gyro)]


def _frame_jitter_px(t, est, start_s=3.0):
    """Horizon jitter between successive 25 fps frames (rms, px at f = 1100 px)."""
    roll = np.array([e.roll for e in est])
    pitch = np.array([e.pitch for e in est])
    frames = np.arange(start_s, t[-1], FRAME_S)
    idx = np.searchsorted(t, frames)
    return FOCAL_PX * math.sqrt(np.mean(np.diff(roll[idx]) ** 2 + np.diff(pitch[idx]) ** 2))


@pytest.mark.parametrize('rate', [100.0, 800.0])
def test_still_rig_defaults_are_steady_to_half_a_pixel(rate):
    sim, t, raw, roll, pitch = _still(rate)
    noise = datasheet_noise_std_g(rate)
    est = _run(AttitudeFilter(sim.truth, noise), t, raw)
    jitter = _frame_jitter_px(t, est)
    assert jitter <= 0.5
    # the former per-sample estimate shakes by several pixels: the test can fail
    single = TiltEstimator(sim.truth, noise)
    assert _frame_jitter_px(t, [single.update(ti, ai) for ti, ai in zip(t, raw)]) > 3.0
    late = t > 3.0
    err = np.degrees([abs(e.roll - r) + abs(e.pitch - p)
                      for e, r, p, k in zip(est, roll, pitch, late) if k])
    assert np.percentile(err, 95) < 0.06
    # the covariance says what the scatter is (within a factor of 2)
    scatter = np.std([e.roll for e, k in zip(est, late) if k])
    stated = math.sqrt(est[-1].cov[0])
    assert 0.5 < scatter / stated < 2.0


def test_motion_costs_little_lag_and_a_slow_creep_none():
    rate = 100.0
    sim = SimulatedAdxl345(rate_hz=rate, poses_deg=[[0, 0], [10, -5], [30, 20], [-20, 40]],
                           dwell_s=3.0, move_s=1.0, seed=2)
    t = np.arange(0.0, 48.0, 1.0 / rate)
    raw, roll, pitch = sim.read_with_truth(t)
    est = _run(AttitudeFilter(sim.truth, datasheet_noise_std_g(rate)), t, raw)
    err = np.degrees(np.hypot([e.roll for e in est] - roll, [e.pitch for e in est] - pitch))
    moving = sim.pose_index(t) < 0
    settled = (~moving) & (np.mod(t, sim.period_s) > 2.0)
    # turns of up to 60 deg/s: the double low-pass keeps up (a 0.04 s low-pass lags 2.4 deg)
    assert np.percentile(err[moving], 95) < 0.8
    assert np.percentile(err[settled], 95) < 0.1   # the still trend settles within ~2 tau
    # a creep of 1 deg/s passes the stillness detector: the still average follows it
    t = np.arange(0.0, 20.0, 1.0 / rate)
    truth = np.radians(1.0) * t
    rng = np.random.default_rng(5)
    raw = specific_force_from_roll_pitch(truth, np.full(t.size, -0.1)) \
        + rng.standard_normal((t.size, 3)) * datasheet_noise_std_g(rate)
    filt = AttitudeFilter(None, datasheet_noise_std_g(rate))
    est = _run(filt, t, raw)
    err = np.degrees(np.abs([e.roll for e in est] - truth))[t > 3.0]
    assert np.percentile(err, 95) < 0.08


def _drive_errors(drive, estimates):
    roll = np.array([e.roll for e in estimates])
    pitch = np.array([e.pitch for e in estimates])
    keep = drive.t > 2.0
    truth = np.stack([-np.sin(drive.pitch), np.cos(drive.pitch) * np.sin(drive.roll),
                      np.cos(drive.pitch) * np.cos(drive.roll)], axis=1)[keep]
    got = np.stack([-np.sin(pitch), np.cos(pitch) * np.sin(roll),
                    np.cos(pitch) * np.cos(roll)], axis=1)[keep]
    return np.degrees(np.arccos(np.clip(np.sum(truth * got, axis=1), -1.0, 1.0))), keep


@pytest.fixture(scope='module')
def drive():
    return simulate_drive(rate_hz=100.0, seed=1)


def test_drive_accelerometer_alone_is_blind_and_says_so(drive):
    settings = FilterSettings(platform_accel_g=0.3)
    est = estimate_series(drive.t, drive.accel_g, settings=settings)
    err, keep = _drive_errors(drive, est)
    assert np.percentile(err, 95) > 10.0   # a 0.3 g turn fakes 17 deg
    std = np.degrees(np.sqrt([e.cov[0] for e in est]))[keep]
    assert np.all(std >= 16.0)            # the covariance covers what a 0.3 g turn fakes
    filt = AttitudeFilter(SensorModel.identity(), settings=settings)
    _run(filt, drive.t[:50], drive.accel_g[:50])
    assert filt.mode == MODE_BLIND


def test_drive_gyro_and_odometry_aids(drive):
    odometry = (drive.odo_t, drive.odo_speed, drive.odo_yaw_rate)
    gyro, keep = _drive_errors(drive, estimate_series(drive.t, drive.accel_g,
                                                      drive.gyro_rad_s))
    odo, _ = _drive_errors(drive, estimate_series(drive.t, drive.accel_g, None, odometry,
                                                  drive.lever_arm_m))
    both_est = estimate_series(drive.t, drive.accel_g, drive.gyro_rad_s, odometry,
                               drive.lever_arm_m)
    both, _ = _drive_errors(drive, both_est)
    assert gyro.max() <= 1.0 and np.percentile(gyro, 95) <= 0.9
    assert np.percentile(odo, 95) <= 1.0
    assert np.percentile(both, 95) <= 0.35
    # honest covariance: the error is within 3 stated standard deviations
    std = np.degrees(np.sqrt([e.cov[0] for e in both_est]))[keep]
    assert np.mean(both <= 3.0 * std) > 0.99


def test_gyro_path_at_rest_keeps_static_accuracy():
    rate = 100.0
    sim, t, raw, roll, pitch = _still(rate, seconds=10.0)
    rng = np.random.default_rng(0)
    bias = np.radians([0.8, -0.5, 0.3])
    gyro = bias + rng.standard_normal((t.size, 3)) * math.radians(0.38)
    filt = AttitudeFilter(sim.truth, datasheet_noise_std_g(rate))
    est = _run(filt, t, raw, gyro)
    assert filt.mode == MODE_GYRO and filt.bias_known
    np.testing.assert_allclose(filt.gyro_bias_rad_s, bias, atol=math.radians(0.1))
    late = t > 3.0
    err = np.degrees([abs(e.roll - r) + abs(e.pitch - p)
                      for e, r, p, k in zip(est, roll, pitch, late) if k])
    assert np.percentile(err, 95) < 0.05
    assert _frame_jitter_px(t, est) <= 0.5


def _pull_away(rate):
    """Pitch error (deg) and y bias (rad/s) left once a 0.3 g pull-away is rejected."""
    filt = AttitudeFilter(settings=FilterSettings(vertical_aid_time_constant_s=0.0))
    errors = []
    for t in np.arange(0.0, 7.0, 1.0 / rate).tolist():
        w = min(max(t - 5.0, 0.0), 1.0)   # level, no rotation; from 5 s a 1 s smooth step
        a = 0.3 * w * w * (3.0 - 2.0 * w)
        vibration = 0.03 * math.sin(2 * math.pi * 12.0 * t) if t >= 3.0 else 0.0   # moving
        est = filt.update(t, (a, 0.0, 1.0 + vibration), (0.0, 0.0, 0.0))
        if t >= 6.0:
            assert filt.rejecting
            errors.append(abs(math.degrees(est.pitch)))
    return max(errors), abs(filt.gyro_bias_rad_s[1])


@pytest.mark.parametrize('rate', [100.0, 800.0])
def test_the_onset_of_an_acceleration_is_taken_back_when_it_is_rejected(rate, monkeypatch):
    # before the low-passed innovation passes rejection_deg the pull follows the
    # acceleration (0.08 deg here, and the integral term learns it as a bias)
    error, bias = _pull_away(rate)
    monkeypatch.setattr(tilt_filter, 'UNDO_TIME_CONSTANT_S', 1e-9)   # nothing taken back
    error_kept, bias_kept = _pull_away(rate)
    assert error_kept > 0.05
    assert error < 0.25 * error_kept
    assert bias < 0.25 * bias_kept


@pytest.mark.parametrize('rate', [100.0, 800.0])
def test_a_steady_pull_that_looks_still_does_not_bring_the_accelerometer_back(
        rate, monkeypatch):
    # on a smooth road the pull away (0.15 g, 6 s) passes the stillness detector; 3 s into
    # its rejection the accelerometer is trusted again only if the still average's
    # magnitude is 1 g (a pull's is sqrt(1 + a^2)): else 8.5 deg of pitch are faked
    drive = simulate_drive(rate_hz=rate, seed=2, vibration_g=0.0)

    def first_14_s():
        est = estimate_series(drive.t, drive.accel_g, drive.gyro_rad_s)
        err, keep = _drive_errors(drive, est)
        return err[drive.t[keep] < 14.0].max()   # the pull away and a cruise

    assert first_14_s() < 0.5
    monkeypatch.setattr(tilt_filter, 'RECOVERY_FORCE_G', math.inf)
    assert first_14_s() > 5.0


def test_bad_gyro_samples_are_bridged_then_dropped_with_a_reason():
    truth = SensorModel.identity()
    raw = specific_force_from_roll_pitch(0.1, -0.2)
    filt = AttitudeFilter(truth)
    t = 0.0
    for _ in range(200):   # learn the bias while still
        filt.update(t, raw, (0.001, 0.0, 0.0))
        t += 0.01
    assert filt.mode == MODE_GYRO
    est = filt.update(t, raw, (math.nan, 0.0, 0.0))
    assert est is not None and filt.gyro_rejections['NaN'] == 1 and filt.mode == MODE_GYRO
    filt.update(t + 0.01, raw, (50.0, 0.0, 0.0))
    assert filt.gyro_rejections['saturated'] == 1
    for k in range(2, 30):   # longer than the bridge: accelerometer only, said by the mode
        est = filt.update(t + 0.01 * k, raw, (math.inf, 0.0, 0.0))
    assert est is not None and filt.mode == MODE_GYRO_BAD
    assert est.roll == pytest.approx(0.1, abs=0.01)


def test_odometry_backwards_and_bad_settings_give_one_reason(tmp_path):
    aid = OdometryAid()
    aid.add(1.0, 5.0, 0.0)
    with pytest.raises(InputError, match='backwards in time'):
        aid.add(0.5, 5.0, 0.0)
    with pytest.raises(InputError, match='NaN'):
        aid.add(2.0, math.nan, 0.0)
    with pytest.raises(InputError, match='backwards in time at row 3'):
        accel_series_g([0.0], [0.0, 1.0, 0.5], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0])
    path = tmp_path / 'odo.csv'
    path.write_text('t,v,yaw_rate\n0.0,1.0,0.0\n0.1,1.0,0.0\n0.05,1.0,0.0\n')
    with pytest.raises(AccelcalError, match=':4: odometry running backwards in time'):
        read_odometry_csv(str(path))
    with pytest.raises(InputError, match='moving_time_constant_s'):
        AttitudeFilter(settings=FilterSettings(moving_time_constant_s=-1.0))


def test_odometry_acceleration_at_the_lever_arm():
    # steady turn: v = 10 m/s, r = 0.2 rad/s; sensor 1 m ahead, 0.5 m left
    t = np.arange(0.0, 2.0, 0.02)
    acc = accel_series_g([1.0], t, np.full(t.size, 10.0), np.full(t.size, 0.2),
                         (1.0, 0.5, 0.0))[0]
    g = 9.80665
    np.testing.assert_allclose(acc, [-0.04 * 1.0 / g, (2.0 - 0.04 * 0.5) / g, 0.0],
                               atol=1e-9)
    aid = OdometryAid((1.0, 0.5, 0.0))
    for ti in t:
        aid.add(ti, 10.0 + 2.0 * ti, 0.0)   # 2 m/s^2 forward
    np.testing.assert_allclose(aid.accel_g(1.0), [2.0 / g, 0.0, 0.0], atol=1e-9)
    assert aid.accel_g(5.0) is None   # stale odometry: unaided
