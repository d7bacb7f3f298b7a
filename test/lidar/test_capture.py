"""Online capture of static positions: scans that arrive after the IMU moved on."""
from accelcal_ros.lidar.capture import CaptureSettings, StaticCapture
import numpy as np


def feed_imu(capture, t0, t1, gravity, moving, rate=50.0, seed=0):
    rng = np.random.default_rng(seed)
    for t in np.arange(t0, t1, 1.0 / rate):
        gyro = rng.normal(0, 0.3 if moving else 0.001, 3)
        accel = np.asarray(gravity) + rng.normal(0, 0.5 if moving else 0.02, 3)
        capture.add_imu(t, accel, gyro)


def test_late_scans_count_for_the_still_period_they_were_taken_in():
    """Scans stamped inside a finished still period, delivered late, capture it."""
    capture = StaticCapture(CaptureSettings(min_static_s=0.5, clouds_per_capture=3))
    g1 = np.array([0.0, 0.0, 9.81])
    feed_imu(capture, 0.0, 0.5, g1, moving=True)
    feed_imu(capture, 0.5, 2.5, g1, moving=False)
    g2 = np.array([0.0, 9.81, 0.0])
    feed_imu(capture, 2.5, 4.0, g2, moving=True)  # the IMU has moved on
    assert not capture.still and not capture.positions
    scan = np.random.default_rng(1).normal(size=(100, 3))
    for t in (1.6, 1.8, 2.0):  # stamped while still, arriving now
        capture.add_cloud(t, scan)
    assert len(capture.positions) == 1
    assert np.allclose(capture.positions[0].gravity_m_s2, g1, atol=0.05)
    capture.add_cloud(3.0, scan)  # stamped while moving: ignored
    assert len(capture.positions) == 1


def test_scan_in_the_current_still_period_is_not_stolen_by_the_previous_one():
    """After a capture the next still period starts fresh; old stamps are ignored."""
    capture = StaticCapture(CaptureSettings(min_static_s=0.5, clouds_per_capture=1))
    g1 = np.array([0.0, 0.0, 9.81])
    feed_imu(capture, 0.0, 2.0, g1, moving=False)
    capture.add_cloud(1.5, np.ones((10, 3)))
    assert len(capture.positions) == 1
    feed_imu(capture, 2.0, 3.0, g1, moving=True)
    capture.add_cloud(1.8, np.ones((10, 3)))  # late scan of an already captured period
    assert len(capture.positions) == 1
