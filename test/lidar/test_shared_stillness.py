"""The LiDAR capture and the offline static segments use the package's one detector."""
from accelcal_ros.lidar import scanner_sim as sim
from accelcal_ros.lidar.capture import CaptureSettings, StaticCapture
from accelcal_ros.lidar.static_segments import longest_static_segment
from accelcal_ros.sensor.stillness import StillnessThresholds
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
import numpy as np
import pytest


def test_capture_defaults_are_the_shared_thresholds():
    """Capture defaults come from StillnessThresholds (the accelerometer one in m/s^2)."""
    shared, settings = StillnessThresholds(), CaptureSettings()
    assert settings.gyro_std_threshold_rad_s == shared.gyro_std_rad_s
    assert settings.gyro_rate_threshold_rad_s == shared.gyro_rate_rad_s
    assert settings.accel_std_threshold_m_s2 == pytest.approx(
        shared.accel_std_g * STANDARD_GRAVITY_M_S2)
    assert settings.stillness_thresholds().accel_std_g == pytest.approx(shared.accel_std_g)


@pytest.mark.parametrize('with_gyro', [True, False])
def test_streaming_and_offline_agree_on_a_simulated_rest(with_gyro):
    """Same log: the capture's still period and the offline segment start together."""
    rng = np.random.default_rng(0)
    log, f_true = sim.simulate_imu_static(sim.rot_x(0.4), 4.0, 200.0, rng, handling_s=1.0)
    gyro = log.gyro if with_gyro else None
    seg = longest_static_segment(log.t, log.accel, gyro, trim_s=0.0)
    capture = StaticCapture(CaptureSettings(min_static_s=1.0))
    for k in range(len(log.t)):
        capture.add_imu(log.t[k], log.accel[k], None if gyro is None else gyro[k])
    assert capture.still
    capture.add_cloud(log.t[-1] - 0.5, np.ones((10, 3)))
    position = capture.positions[0]
    assert np.linalg.norm(position.gravity_m_s2 - f_true) < 0.01
    assert np.linalg.norm(seg.gravity_m_s2 - f_true) < 0.01
    assert abs(capture._current.start_s - seg.t_start) < 0.05
    assert 1.0 <= seg.t_start < 1.4


def test_shock_ends_the_still_period():
    """A saturated reading (a knock) ends the capture's still period, as motion does."""
    capture = StaticCapture(CaptureSettings(min_static_s=0.5))
    g = np.array([0.0, 0.0, STANDARD_GRAVITY_M_S2])
    rng = np.random.default_rng(1)
    for t in np.arange(0.0, 2.0, 0.01):
        capture.add_imu(t, g + rng.normal(0, 0.01, 3), rng.normal(0, 0.001, 3))
    assert capture.still
    capture.add_imu(2.0, [0.0, 0.0, 25.0], [0.0, 0.0, 0.0])
    capture.add_imu(2.01, g, [0.0, 0.0, 0.0])
    assert not capture.still
