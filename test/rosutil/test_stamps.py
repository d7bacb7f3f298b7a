"""The header-stamp order rule every IMU consumer shares (pure: no graph)."""
from accelcal_ros.rosutil.stamps import (JUMPED_BACK, OUT_OF_ORDER, StampOrder,
                                         TIME_JUMP_BACK_S, UNSTAMPED, USE)


def test_order_rule_use_skip_and_restart():
    """
    After the previous stamp: used; 0, repeated or a little late: skipped; far back: used.

    Before it the attitude node published samples stamped 0 and stamps running backwards
    (a tilted sensor's roll crawled 0.19 -> 13.9 deg), and a calibration session fed stamp-0
    samples answered capture with "moving (motion 1.6 mg > threshold 10.0 mg)".
    """
    order = StampOrder()
    verdicts = [order.check(t) for t in (0.0, 5.0, 5.0, 6.0, 5.5, 6.0 - TIME_JUMP_BACK_S,
                                         0.0, 7.0, 2.0, 2.01)]
    assert verdicts == [UNSTAMPED, USE, OUT_OF_ORDER, USE, OUT_OF_ORDER, JUMPED_BACK,
                        UNSTAMPED, USE, JUMPED_BACK, USE]
    assert order.skipped == 4 and order.jump_s == 5.0 and order.last == 2.01
    assert 'stamp 0' in order.reason(UNSTAMPED, 'imu/data_raw', '')
    assert 'not after the previous' in order.reason(OUT_OF_ORDER, 'imu/data_raw', '')
    assert 'jumped back by 5.000 s' in order.reason(JUMPED_BACK, 'imu/data_raw', 'restarts')
    order.reset()
    assert order.check(1.0) == USE
