"""Online capture of static positions: scans that arrive after the IMU moved on."""
from accelcal_ros.lidar.capture import CaptureSettings, StaticCapture
import numpy as np
import pytest


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


def test_late_scans_reach_a_still_period_before_the_last():
    """After a stall, scans of two periods ago still capture their own period."""
    capture = StaticCapture(CaptureSettings(min_static_s=0.5, clouds_per_capture=2))
    gravities = [np.array(g) for g in ([0.0, 0.0, 9.81], [0.0, 9.81, 0.0], [9.81, 0.0, 0.0])]
    for k, g in enumerate(gravities):
        feed_imu(capture, 3.0 * k, 3.0 * k + 0.5, g, moving=True, seed=k)
        feed_imu(capture, 3.0 * k + 0.5, 3.0 * k + 3.0, g, moving=False, seed=k)
    feed_imu(capture, 9.0, 9.5, gravities[0], moving=True)
    scan = np.ones((10, 3))
    for t in (1.5, 4.5, 1.7, 7.5, 4.7, 7.7):   # periods 1, 2, 3 interleaved, all late
        capture.add_cloud(t, scan)
    assert [p.name for p in capture.positions] == ['pos01', 'pos02', 'pos03']
    for position, g in zip(capture.positions, gravities):
        assert np.allclose(position.gravity_m_s2, g, atol=0.05)
    capture.add_cloud(6.2, scan)   # stamped while moving between periods 2 and 3
    assert len(capture.positions) == 3


def resting_with_one_scan():
    """Return a capture (2 scans per position) at rest 0-1.5 s with one scan, and g."""
    capture = StaticCapture(CaptureSettings(min_static_s=0.5, clouds_per_capture=2))
    g = np.array([0.0, 0.0, 9.81])
    feed_imu(capture, 0.0, 1.5, g, moving=False)
    capture.add_cloud(1.2, np.ones((10, 3)))
    return capture, g


def test_a_gap_at_the_same_attitude_continues_the_still_period():
    """Scans before and after an IMU gap add up; a scan inside the gap is not used."""
    capture, g = resting_with_one_scan()
    feed_imu(capture, 1.9, 2.2, g, moving=False, seed=1)  # 0.4 s gap: not still yet
    assert not capture.still
    capture.add_cloud(1.7, np.full((10, 3), 7.0))   # stamped inside the gap
    assert not capture.positions
    feed_imu(capture, 2.2, 3.0, g, moving=False, seed=2)
    assert capture.still
    position = capture.add_cloud(2.8, np.ones((10, 3)))
    assert position is not None and np.all(position.points == 1.0)
    feed_imu(capture, 3.5, 4.5, g, moving=False, seed=3)   # another gap, same attitude
    capture.add_cloud(4.0, np.ones((10, 3)))
    capture.add_cloud(4.2, np.ones((10, 3)))
    assert len(capture.positions) == 1   # the same period, captured once
    feed_imu(capture, 4.5, 5.0, g, moving=True, seed=4)   # motion re-arms
    feed_imu(capture, 5.0, 6.5, g, moving=False, seed=5)
    capture.add_cloud(6.0, np.ones((10, 3)))
    capture.add_cloud(6.2, np.ones((10, 3)))
    assert len(capture.positions) == 2


def test_gap_then_motion_is_a_new_period_even_at_the_same_attitude():
    """Motion seen after a gap forbids continuing the period that the gap ended."""
    capture, g = resting_with_one_scan()
    feed_imu(capture, 1.9, 2.6, g, moving=True, seed=1)
    feed_imu(capture, 2.6, 4.0, g, moving=False, seed=2)
    capture.add_cloud(3.5, np.ones((10, 3)))
    assert not capture.positions   # one scan in each period: neither is complete


def replay(capture, events):
    """Feed ``(arrival_s, kind, stamp_s, payload)`` events in arrival order."""
    for _, kind, stamp, payload in sorted(events, key=lambda e: e[0]):
        if kind == 'imu':
            capture.add_imu(stamp, *payload)
        else:
            capture.add_cloud(stamp, payload)


@pytest.mark.parametrize('seed', range(6))
def test_stalled_receiver_still_captures_every_position(seed):
    """
    The graph test's protocol, delivered as a stalled, lossy process receives it.

    Five positions (0.5 s moving, 2.4 s still, IMU 50 Hz, 40 scans from 0.6 s after the
    rest began, 20 per capture). The receiver stalls for 1-4 s at a random moment and
    then works off the backlog, scans ahead of the IMU or up to 3 s behind it;
    best-effort IMU samples are lost in runs of 0.3 s (scans taken then are not used).
    Every position is still captured once, with its own gravity.
    """
    rng = np.random.default_rng(seed)
    gravities = [9.81 * v / np.linalg.norm(v) for v in rng.normal(size=(5, 3))]
    events, t = [], 0.0
    stall_at, stall_s = rng.uniform(1.0, 12.0), rng.uniform(1.0, 4.0)
    drain_s = {'i': rng.uniform(0.05, 1.0), 'c': rng.uniform(0.05, 1.0)}  # backlog per topic
    resend_s = {'i': 0.0, 'c': rng.uniform(0.0, 3.0)}  # reliable scans: resent after a heartbeat
    lost = rng.uniform(0.0, 2.6, 3) + [0.0, 5.8, 11.6]   # 0.3 s each, in positions 1, 3, 5
    last = {'i': 0.0, 'c': 0.0}

    def arrival(stamp, topic):
        """Each topic stays in order; the stall's backlog drains at its own pace."""
        if stall_at <= stamp <= stall_at + stall_s:
            backlog = drain_s[topic] * (stamp - stall_at) / stall_s
            at = stall_at + stall_s + resend_s[topic] + backlog
        else:
            at = stamp + 0.001 * (topic == 'c')
        last[topic] = max(at, last[topic] + 1e-4)
        return last[topic]

    for g in gravities:
        start_still, end = t + 0.5, t + 2.9
        for k, stamp in enumerate(np.arange(t, end, 0.02)):
            moving = stamp < start_still
            if np.any((lost <= stamp) & (stamp < lost + 0.3)):
                continue
            sample = (g + rng.normal(0, 0.5 if moving else 0.02, 3),
                      rng.normal(0, 0.3 if moving else 0.001, 3))
            events.append((arrival(stamp, 'i'), 'imu', stamp, sample))
        for stamp in start_still + 0.6 + 0.02 * np.arange(40):
            events.append((arrival(stamp, 'c'), 'cloud', stamp, np.full((5, 3), stamp)))
        t = end
    capture = StaticCapture(CaptureSettings(min_static_s=0.5, clouds_per_capture=20))
    replay(capture, events)
    assert len(capture.positions) == 5
    for position, g in zip(capture.positions, gravities):
        assert np.degrees(np.arccos(np.clip(
            position.gravity_m_s2 @ g / np.linalg.norm(position.gravity_m_s2) / 9.81,
            -1, 1))) < 0.2


def test_scans_in_a_second_gap_before_the_rest_resumes_are_not_used():
    """Two gaps with a few samples between: everything unseen until the rest resumes."""
    capture, g = resting_with_one_scan()
    feed_imu(capture, 1.9, 2.0, g, moving=False, seed=1)   # gap, 5 samples, gap again
    feed_imu(capture, 2.4, 3.2, g, moving=False, seed=2)
    assert capture.still
    capture.add_cloud(2.2, np.full((10, 3), 7.0))   # stamped inside the second gap
    capture.add_cloud(1.95, np.full((10, 3), 7.0))  # between the gaps: never judged still
    assert not capture.positions
    position = capture.add_cloud(3.0, np.ones((10, 3)))
    assert position is not None and np.all(position.points == 1.0)


def test_manual_capture_merges_the_latest_scans_only():
    """Without auto capture a long rest keeps only the last clouds_per_capture scans."""
    capture = StaticCapture(CaptureSettings(min_static_s=0.5, clouds_per_capture=2, auto=False))
    feed_imu(capture, 0.0, 1.0, [0.0, 0.0, 9.81], moving=False)
    for k, t in enumerate((0.6, 0.7, 0.8, 0.9)):
        capture.add_cloud(t, np.full((3, 3), float(k)))
    assert not capture.positions
    position, reason = capture.capture_now()
    assert reason == 'captured' and sorted(set(position.points[:, 0])) == [2.0, 3.0]
    assert capture.capture_now()[0] is None


def test_scans_beyond_the_pending_limit_are_counted_as_overflowed():
    """Without IMU samples scans wait; beyond max_pending_scans the oldest are counted."""
    capture = StaticCapture(CaptureSettings(min_static_s=0.5, clouds_per_capture=2,
                                            max_pending_scans=5))
    for k in range(12):
        capture.add_cloud(0.1 * k, np.zeros((4, 3)))
    assert capture.scans_overflowed == 12 - 5
