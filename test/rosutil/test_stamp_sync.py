"""Tests of the message_filters equivalent (stamp matching)."""
from accelcal_ros.rosutil.stamp_sync import StampMatcher


def test_nearest_within_tolerance_and_missing_stream():
    """Each stream gives its nearest item within tolerance; a silent one gives None."""
    m = StampMatcher(['cam0', 'cam1', 'cam2'], depth=5)
    for k in range(5):
        m.add('cam0', 10.0 + 0.1 * k, f'a{k}')
        m.add('cam1', 10.003 + 0.1 * k, f'b{k}')
    match = m.nearest(10.2, tolerance_s=0.01)
    assert match['cam0'] == (10.2, 'a2')
    assert match['cam1'][1] == 'b2'
    assert match['cam2'] is None
    assert m.nearest(10.25, tolerance_s=0.01)['cam0'] is None


def test_out_of_order_arrival_and_depth():
    """Out-of-order stamps are sorted; only the newest ``depth`` items are kept."""
    m = StampMatcher(['x'], depth=3)
    for stamp in (3.0, 1.0, 2.0, 5.0, 4.0):
        m.add('x', stamp, stamp)
    assert m.latest_stamp() == 5.0
    assert m.nearest(1.0, 0.5)['x'] is None  # dropped (oldest beyond depth)
    assert m.nearest(3.1, 0.5)['x'] == (3.0, 3.0)
    m.clear()
    assert m.latest_stamp() is None
