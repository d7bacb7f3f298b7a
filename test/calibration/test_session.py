"""Calibration session: auto capture, progress, services out of order, bad samples."""
from accelcal_ros.calibration.coverage import recommended_directions, roll_pitch_deg_of
from accelcal_ros.calibration.session import Calibrator, CalibratorConfig
from accelcal_ros.driver.sim_sensor import SimulatedAdxl345
from accelcal_ros.errors import CalibrationError
import numpy as np
import pytest

pytestmark = pytest.mark.filterwarnings('ignore:Gimbal lock')


def _sim(count=14, dwell_s=1.5, move_s=0.7, seed=1, truth=None):
    poses = roll_pitch_deg_of(recommended_directions(count))
    sim = SimulatedAdxl345(truth=truth, poses_deg=poses, dwell_s=dwell_s, move_s=move_s,
                           rate_hz=100.0, seed=seed)
    t = np.arange(0.0, sim.period_s * count, 0.01)
    return sim, t, sim.read(t)


def test_auto_capture_of_every_dwell_and_fit_against_truth():
    sim, t, a = _sim()
    cal = Calibrator()
    cal.start()
    events = []
    for k in range(0, len(t), 37):  # uneven chunks, as messages arrive
        events += cal.add_samples(t[k:k + 37], a[k:k + 37])
    assert sum(e.startswith('captured') for e in events) == 14
    progress = cal.progress()
    assert progress.positions == 14 and progress.coverage == 1.0
    assert 0.0 < progress.predicted_tilt_error_deg < 0.1
    result = cal.finish()
    assert not cal.active
    np.testing.assert_allclose(result.sensor_model.scale, sim.truth.scale, atol=1e-3)
    np.testing.assert_allclose(result.sensor_model.bias, sim.truth.bias, atol=1e-3)
    assert np.all(np.abs(result.sensor_model.scale - sim.truth.scale)
                  < 5 * result.scale_std + 2e-4)


def test_progress_grows_and_hints_name_missing_orientations():
    sim, t, a = _sim()
    cal = Calibrator()
    cal.start()
    cal.add_samples(t[:300], a[:300])  # first position only
    progress = cal.progress()
    assert progress.positions == 1 and progress.predicted_tilt_error_deg is None
    assert progress.coverage < 0.2 and len(progress.hints) == 3
    assert 'more positions' in progress.note
    assert '1 positions (need 10)' in progress.text()


def test_same_orientation_twice_not_captured_again():
    sim = SimulatedAdxl345(poses_deg=[(0, 0), (5, 0)], dwell_s=1.5, move_s=0.5, seed=0)
    t = np.arange(0.0, 4.0, 0.01)
    cal = Calibrator()
    cal.start()
    events = cal.add_samples(t, sim.read(t))
    assert sum(e.startswith('captured') for e in events) == 1
    assert any('only' in e and 'not captured' in e for e in events)


def test_manual_capture_refused_while_moving_and_twice():
    sim, t, a = _sim()
    cal = Calibrator(CalibratorConfig(auto_capture=False))
    cal.start()
    moving = int((sim.dwell_s + 0.35) / 0.01)
    cal.add_samples(t[:moving], a[:moving])
    with pytest.raises(CalibrationError, match='moving'):
        cal.capture_now()
    still = int((sim.period_s + 1.0) / 0.01)
    cal.add_samples(t[moving:still], a[moving:still])
    cap = cal.capture_now()
    assert cap.index == 0 and cap.samples > 50
    with pytest.raises(CalibrationError, match='already captured'):
        cal.capture_now()


def test_services_out_of_order_refused_with_what_to_call():
    cal = Calibrator()
    for call in (cal.finish, cal.cancel, cal.capture_now):
        with pytest.raises(CalibrationError, match='calibration/start'):
            call()
    assert cal.add_samples([0.0], [[0.0, 0.0, 1.0]]) == []
    cal.start()
    with pytest.raises(CalibrationError, match='already running'):
        cal.start()
    assert cal.cancel() == 0
    cal.start()  # a new session after cancel is fine


def test_too_few_positions_refused_session_stays_open():
    sim, t, a = _sim(count=14)
    cal = Calibrator()
    cal.start()
    cut = int(sim.period_s * 4 / 0.01)
    cal.add_samples(t[:cut], a[:cut])
    with pytest.raises(CalibrationError, match='too few'):
        cal.finish()
    assert cal.active
    cal.add_samples(t[cut:], a[cut:])
    assert cal.finish().positions == 14


def test_nan_and_saturated_samples_reported_once_and_not_used():
    sim, t, a = _sim()
    a = a.copy()
    a[10::97] = np.nan
    a[20::389, 0] = 16.0  # shocks: each ends a dwell
    cal = Calibrator()
    cal.start()
    events = cal.add_samples(t, a)
    assert sum(e.startswith('rejected') for e in events) == 1
    assert cal.detector.rejected_nan > 10 and cal.detector.rejected_saturated > 3
    result = cal.finish()
    np.testing.assert_allclose(result.sensor_model.bias, sim.truth.bias, atol=2e-3)


def test_a_still_dwell_reading_zero_is_not_captured():
    """An all-zero reading (stuck sensor) has no direction: said, not captured, no warning."""
    import warnings

    calibrator = Calibrator(CalibratorConfig())
    calibrator.start()
    t = np.arange(300) * 0.01
    with warnings.catch_warnings():
        warnings.simplefilter('error', RuntimeWarning)
        events = calibrator.add_samples(t, np.zeros((300, 3)))
        with pytest.raises(CalibrationError, match='no gravity direction'):
            calibrator.capture_now()
        events += calibrator.flush()
    assert not calibrator.captures
    assert [e for e in events if 'no gravity direction' in e]
