"""
imu_driver on the register-level simulated buses, started as a user would, in a DDS graph.

``backend:=sim`` with ``sim.bus:=i2c|spi``: every transaction costs its wire time at
``bus_speed_hz``, and the driver's own I2C/SPI code reads the simulated chip. Losses are
attributed: the chip's FIFO (``sim_fifo_dropped_samples``, the simulation's truth, and the
driver's ``fifo_overruns``) against what DDS did not deliver to the subscriber
(``samples_published`` minus received).
"""
import re
import time

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu
from std_srvs.srv import Trigger

pytestmark = pytest.mark.graph


def stamp(msg):
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def latest_values(diag):
    """Key/values of the newest imu_driver status, with the probe's receive time."""
    msgs, times = diag.snapshot()
    for msg, t in zip(reversed(msgs), reversed(times)):
        for status in msg.status:
            if 'imu_driver' in status.name:
                return t, {kv.key: kv.value for kv in status.values}
    return None, {}


def wait_values(diag, condition, timeout):
    """Wait for a diagnostics status that satisfies ``condition``; return (time, values)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        t, values = latest_values(diag)
        if values and condition(values):
            return t, values
        time.sleep(0.05)
    raise TimeoutError(f'no matching diagnostics in {timeout} s (last: {latest_values(diag)})')


def test_i2c_at_100_khz_refuses_3200_hz_with_the_reason(graph):
    """The datasheet rule and the bus time: one line naming the limit and 200 Hz."""
    proc = graph.start('imu_driver', {'backend': 'sim', 'sim.bus': 'i2c', 'rate_hz': 3200.0,
                                      'bus_speed_hz': 100000.0})
    assert proc.wait_exit(timeout=30.0) == 1
    out = proc.output()
    assert 'rate_hz 3200 is not sustainable on I2C at 100 kHz' in out
    assert 'only over SPI at >= 2 MHz' in out and 'fastest rate that works here is 200 Hz' in out
    assert 'Traceback' not in out


@pytest.mark.parametrize('bus, speed, rate, reads', [('i2c', 400000.0, 800.0, 'polling'),
                                                     ('spi', 5000000.0, 3200.0, 'polling'),
                                                     ('spi', 5000000.0, 800.0, 'interrupt')])
def test_sustainable_rate_is_achieved_without_loss(graph, bus, speed, rate, reads):
    """
    10 s at the full rate: the bus loses nothing; stamps evenly spaced.

    Losses are attributed. The sensor side: an overrun after a drain that started in time
    is the bus's fault (must be 0, and the wire at most half busy); one after the host did
    not run the driver for a FIFO's worth of time (32 samples: 40 ms at 800 Hz, 10 ms at
    3200 Hz) is the loaded host's (reported: on an idle machine it is 0 too). What DDS
    drops on the way to a best-effort subscriber is measured and bounded loosely; the
    received stamps lie on the sample grid.
    """
    window_s = 10.0
    qos = QoSProfile(depth=10000, reliability=ReliabilityPolicy.BEST_EFFORT)
    imu = graph.collect(Imu, 'imu/data_raw', qos)
    diag = graph.collect(DiagnosticArray, '/diagnostics', 50)
    graph.start('imu_driver', {'backend': 'sim', 'sim.bus': bus, 'bus_speed_hz': speed,
                               'rate_hz': rate, 'diagnostics_period_s': 0.5, 'reads': reads,
                               'sim.poses_deg': [0.0, 0.0]})
    imu.wait_for(int(rate), timeout=30.0)   # discovery done, streaming
    t_start, start = wait_values(diag, lambda v: int(v['samples_published']) > 2 * rate,
                                 30.0)
    imu.clear()
    t0 = time.monotonic()
    t_end, end = wait_values(diag, lambda v: int(v['samples_published'])
                             >= int(start['samples_published']) + window_s * rate
                             and time.monotonic() - t0 > window_s, 60.0)
    msgs, _ = imu.snapshot()

    def delta(key):
        return int(end[key]) - int(start[key])

    published = delta('samples_published')
    dropped_by_fifo = delta('sim_fifo_dropped_samples')
    # wire time over the time between the two statuses (on a loaded host more than
    # window_s may pass before the end condition holds)
    busy = (float(end['sim_bus_busy_s']) - float(start['sim_bus_busy_s'])) / \
        max(t_end - t_start, window_s)
    report = (f'{bus} {speed:g} Hz at {rate:g} Hz: published {published}, received '
              f'{len(msgs)} (over the probe window), FIFO dropped '
              f'{dropped_by_fifo} (overruns: host stall {delta("fifo_overruns_host_stall")}, '
              f'bus too slow {delta("fifo_overruns_bus_too_slow")}), bus busy {100 * busy:.1f} %')
    print(report)
    assert end['bus'] == bus and float(end['bus_speed_hz']) == speed
    assert end['reads'].startswith(reads)
    # the bus sustains the rate: the wire at most half busy, and no overrun blamed on it --
    # but for the rare one that the blame (wire time over the clock time between two
    # drains, which a drain preempted by a loaded host distorts) gets wrong: at most 1 in
    # 50 of the host's own stalls (measured beside a 2-core load: 1 in 152); idle: none
    assert busy < 0.5, report
    assert delta('fifo_overruns_bus_too_slow') <= delta('fifo_overruns_host_stall') // 50, \
        report
    # every sample the sensor's FIFO dropped is explained by a stall of this (loaded)
    # host, and the driver's own estimate of the loss matches the chip's count
    if dropped_by_fifo:
        assert delta('fifo_overruns_host_stall') > 0, report
    assert delta('fifo_lost_samples_estimated') == pytest.approx(dropped_by_fifo, rel=0.25,
                                                                 abs=32), report
    assert delta('sim_samples_generated') - dropped_by_fifo - published <= 32, report
    assert published >= 0.98 * window_s * rate - dropped_by_fifo, report
    # what DDS delivers to a best-effort Python probe depends on the host's load, not on
    # the driver: enough for the stamp statistics below (a second's worth) is asked
    assert len(msgs) >= rate, report
    stamps = np.sort([stamp(m) for m in msgs])
    # the period is the measured output data rate; where the host stalls often, the
    # measuring window restarts at each overrun and the estimate is off by a few 0.1 %
    period_s = float(np.median(np.diff(stamps)))
    assert period_s * rate == pytest.approx(1.0, rel=1e-2)
    steps = np.diff(stamps) / period_s
    assert np.all(steps >= 0.49)
    # gaps are whole sample periods (a message DDS did not deliver), never a shifted grid:
    # a step off the grid is one across a restart of the stamp chain (an overrun or a
    # resync, each counted by the driver: on a loaded host there can be many), or one of
    # the few (5 %, as before) the chain's period correction moves
    off_grid = int(np.count_nonzero(np.abs(steps - np.round(steps)) >= 0.1))
    restarts = delta('fifo_overruns') + (int(end.get('fifo_stamp_resyncs', 0))
                                         - int(start.get('fifo_stamp_resyncs', 0)))
    assert off_grid <= restarts + 0.05 * len(steps), \
        f'{report}; {off_grid} of {len(steps)} steps off the grid, {restarts} restarts'


def test_unsustainable_rate_runs_when_asked_and_reports_its_losses(graph):
    """I2C at 100 kHz and 1600 Hz with allow_unsustainable_rate: WARN, achieved rate, losses.

    1600 samples/s x 831 us per 6-byte read is 1.33 s of wire time per second: the bus
    cannot keep up whatever the host's load (800 Hz would fit in 0.67 s/s: whether it loses
    samples then depends on the host, not on the bus).
    """
    diag = graph.collect(DiagnosticArray, '/diagnostics', 50)
    proc = graph.start('imu_driver', {'backend': 'sim', 'sim.bus': 'i2c', 'rate_hz': 1600.0,
                                      'bus_speed_hz': 100000.0, 'diagnostics_period_s': 0.5,
                                      'allow_unsustainable_rate': True})
    # (which overrun is the bus's and which the host's is a heuristic: not asserted here)
    _, values = wait_values(diag, lambda v: int(v['fifo_lost_samples_estimated']) > 0
                            and int(v['samples_published']) > 2000, 60.0)
    assert 'running anyway' in proc.output() and 'only over SPI at >= 2 MHz' in proc.output()
    msgs, _ = diag.snapshot()
    status = [s for a in msgs for s in a.status if 'imu_driver' in s.name][-1]
    assert status.level == status.WARN and 'unsustainable rate, achieved' in status.message
    # the bus gives at most 1 / (831 us + status reads), about 1100 Hz: well below 1600 Hz
    assert float(values['rate_hz_achieved']) < 0.95 * 1600.0
    assert int(values['fifo_lost_samples_estimated']) > 0
    assert int(values['sim_fifo_dropped_samples']) > 0


def test_self_test_service_passes_a_healthy_and_fails_a_broken_sensor(graph):
    """``imu_driver/self_test``: per-axis change and verdict; the stream resumes after it."""
    imu = graph.collect(Imu, 'imu/data_raw')
    params = {'backend': 'sim', 'sim.bus': 'spi', 'rate_hz': 200.0, 'sim.poses_deg': [0.0, 0.0]}
    graph.start('imu_driver', params)
    imu.wait_for(20, timeout=30.0)
    response = graph.call(Trigger, '/imu_driver/self_test', timeout=30.0)
    assert response.success, response.message
    assert 'self-test passed at VS = 3.3 V' in response.message
    assert response.message.count(') pass') == 3
    imu.clear()
    imu.wait_for(20, timeout=20.0)   # streaming again

    broken = dict(params, **{'sim.self_test_broken_axes': 'z'})
    graph.start('imu_driver', broken, name='imu_driver_broken',
                remaps={'__node': 'imu_driver_broken'})
    response = graph.call(Trigger, '/imu_driver_broken/self_test', timeout=30.0)
    assert not response.success
    # the broken axis does not move (its reading is noise, a few LSB at most, far below the
    # datasheet's 110 LSB minimum): failed
    broken_z = re.search(r'FAILED .* z ([+-]\d+) LSB .* FAIL$', response.message)
    assert broken_z and abs(int(broken_z.group(1))) < 20, response.message
    assert 'x +' in response.message and 'y -' in response.message
