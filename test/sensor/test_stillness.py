"""The one stillness detector: dwells of the simulated ADXL345, gyro turns, offline scan."""
from accelcal_ros.driver.sim_sensor import SimulatedAdxl345
from accelcal_ros.errors import InputError
from accelcal_ros.sensor.stillness import still_segments, StillnessDetector, StillnessThresholds
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
import numpy as np
import pytest


def _recording(rate_hz=100.0, dwell_s=2.0, move_s=1.0, poses=6, seed=0):
    sim = SimulatedAdxl345(poses_deg=[(0, 0), (90, 0), (0, 60), (180, 0), (-90, 30),
                                      (0, -60)][:poses],
                           rate_hz=rate_hz, dwell_s=dwell_s, move_s=move_s, seed=seed)
    t = np.arange(0.0, sim.period_s * poses, 1.0 / rate_hz)
    return sim, t, sim.read(t)


@pytest.mark.parametrize('rate_hz', [100.0, 800.0])
def test_every_dwell_found_with_its_true_mean(rate_hz):
    sim, t, a = _recording(rate_hz)
    det = StillnessDetector()
    det.add_many(t, a)
    det.flush()
    segments = [s.final for s in det.ended if s.final is not None
                and s.final.duration_s >= 1.0]
    assert len(segments) == 6
    for k, seg in enumerate(segments):
        # Each segment lies inside dwell k (start within the dwell, at most 0.15 s of
        # the slow start of the next move included).
        assert k * sim.period_s - 0.15 <= seg.t_start_s < k * sim.period_s + 0.5
        assert seg.t_end_s <= k * sim.period_s + sim.dwell_s + 0.15
        assert t[seg.start] == seg.t_start_s and t[seg.stop - 1] == seg.t_end_s
        truth = sim.truth.distort(sim.true_specific_force([k * sim.period_s + 0.5]))[0]
        assert np.all(np.abs(seg.accel_mean - truth) < 5 * seg.accel_std_of_mean + 4e-4)


def test_motion_is_not_still():
    sim, t, a = _recording()
    det = StillnessDetector()
    still_while_moving = 0
    for ti, ai in zip(t, a):
        det.add(ti, ai)
        mid_move = (ti % sim.period_s) - sim.dwell_s
        if 0.2 < mid_move < 0.8 and det.still:
            still_while_moving += 1
    assert still_while_moving == 0


def test_nan_skipped_saturated_rejected_and_breaks_the_dwell():
    sim, t, a = _recording(poses=2)
    a = a.copy()
    a[50] = np.nan
    a[120, 2] = 16.0
    det = StillnessDetector()
    used = det.add_many(t, a)
    assert used == len(t) - 2
    assert det.rejected_nan == 1 and det.rejected_saturated == 1
    assert det.ended and det.ended[0].blocks[-1].t_end < t[120]
    det.flush()
    for seg in det.ended:
        if seg.final is not None:
            assert np.all(np.isfinite(seg.final.accel_mean))
            assert seg.final.accel_mean[2] < 1.5


def test_time_going_backwards_breaks_the_dwell():
    det = StillnessDetector()
    t = np.arange(0.0, 2.0, 0.01)
    a = np.tile([0.0, 0.0, 1.0], (len(t), 1))
    det.add_many(t, a)
    assert det.still
    det.add(0.5, [0.0, 0.0, 1.0])
    assert not det.still
    assert det.ended


def _turning_imu(rate_hz=200.0, seed=1):
    """Still 0-3 s, a slow yaw turn (0.2 rad/s) 3-6 s, still 6-9 s; accel in m/s^2."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 9.0, 1.0 / rate_hz)
    accel = np.tile([0.0, 0.0, STANDARD_GRAVITY_M_S2], (t.size, 1))
    accel += rng.normal(0.0, 0.02, accel.shape)
    gyro = rng.normal(0.0, 0.002, (t.size, 3))
    gyro[(t >= 3.0) & (t < 6.0), 2] += 0.2   # a yaw turn leaves the accelerometer alone
    return t, accel, gyro


def test_gyro_sees_a_turn_the_accelerometer_cannot():
    t, accel, gyro = _turning_imu()
    accel_only = still_segments(t, accel, accel_unit_m_s2=1.0)
    assert len(accel_only) == 1 and accel_only[0].duration_s > 8.5
    with_gyro = still_segments(t, accel, gyro, accel_unit_m_s2=1.0)
    assert len(with_gyro) == 2
    first, second = with_gyro
    assert first.t_start_s < 0.1 and 2.5 < first.t_end_s <= 3.05
    assert 5.95 <= second.t_start_s < 6.5 and second.t_end_s > 8.9
    assert np.allclose(first.gyro_mean_rad_s, 0.0, atol=0.002)
    assert first.accel_mean[2] == pytest.approx(STANDARD_GRAVITY_M_S2, abs=0.01)


@pytest.mark.parametrize('case', ['sim', 'gyro', 'glitches'])
def test_offline_scan_equals_streaming(case):
    gyro = None
    unit = STANDARD_GRAVITY_M_S2
    if case == 'gyro':
        t, a, gyro = _turning_imu()
        unit = 1.0
    else:
        _, t, a = _recording(200.0)
        if case == 'glitches':
            a = a.copy()
            a[[40, 41, 700]] = np.nan
            a[1500, 0] = -3.0
            t = t.copy()
            t[2000:] += 0.8   # a gap
    det = StillnessDetector(accel_unit_m_s2=unit)
    det.add_many(t, a, gyro)
    det.flush()
    streamed = [s.final for s in det.ended
                if s.final is not None and s.final.duration_s >= 1.0]
    offline = still_segments(t, a, gyro, accel_unit_m_s2=unit)
    assert len(offline) == len(streamed) > 1
    for x, y in zip(offline, streamed):
        assert (x.start, x.stop, x.samples) == (y.start, y.stop, y.samples)
        assert np.allclose(x.accel_mean, y.accel_mean, rtol=0, atol=1e-12)
        assert np.allclose(x.accel_std, y.accel_std, rtol=0, atol=1e-9)


def test_thresholds_checked():
    with pytest.raises(InputError, match='window_s'):
        StillnessDetector(StillnessThresholds(window_s=0.0))
    with pytest.raises(InputError, match='accel_std_g'):
        still_segments([0.0], [[0, 0, 1]], thresholds=StillnessThresholds(accel_std_g=-1))
    with pytest.raises(InputError, match='3 times for 2'):
        still_segments([0.0, 1.0, 2.0], [[0, 0, 1]] * 2)
