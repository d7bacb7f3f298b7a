"""
The node runner as the installed executables use it: executors, signals, fatal errors.

Every case starts a real node process (``imu_driver``, the sim backend at 800 Hz: a
publishing thread that was killed mid-publish by Ctrl-C, ``attitude`` for delivery) and
stops it the way a terminal (SIGINT) or ``ros2 launch``/systemd (SIGTERM) does.
"""
import signal

from geometry_msgs.msg import Vector3Stamped
import pytest
from rcl_interfaces.msg import Log
from rclpy.qos import QoSDurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu

pytestmark = pytest.mark.graph

_DRIVER_800 = {'backend': 'sim', 'rate_hz': 800.0, 'sim.dwell_s': 0.5, 'sim.move_s': 0.2}


def _stop_with(proc, sig, timeout=15.0):
    proc.proc.send_signal(sig)
    return proc.wait_exit(timeout=timeout)


@pytest.mark.parametrize('executor', ['events', 'single', 'multi'])
@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_driver_at_800hz_stops_cleanly(graph, monkeypatch, executor, sig):
    """Exit 0, no traceback (no RCLError from the publishing thread) on SIGINT and SIGTERM."""
    monkeypatch.setenv('ACCELCAL_EXECUTOR', executor)
    imu = graph.collect(Imu, 'imu/data_raw')
    proc = graph.start('imu_driver', _DRIVER_800, name=f'driver_{executor}_{sig.name}')
    imu.wait_for(200, timeout=20.0)  # publishing at full rate when the signal arrives
    assert _stop_with(proc, sig) == 0
    out = proc.output()
    assert 'Traceback' not in out and 'RCLError' not in out, out


@pytest.mark.parametrize('executor', ['events', 'single', 'multi'])
def test_attitude_delivers_and_answers_services(graph, monkeypatch, executor):
    """The node's subscription, publishers and parameter services work on every executor."""
    monkeypatch.setenv('ACCELCAL_EXECUTOR', executor)
    attitude = graph.collect(Vector3Stamped, 'attitude')
    graph.start('imu_driver', {'backend': 'sim', 'rate_hz': 100.0})
    proc = graph.start('attitude', name=f'attitude_{executor}')
    attitude.wait_for(50, timeout=20.0)
    for attempt in range(2):  # a first answer can be lost while the reply path matches
        try:
            result = graph.set_parameters('attitude', {'time_constant_s': 0.5}, timeout=30.0)
            values = graph.get_parameters('attitude', ['time_constant_s'], timeout=30.0)
            break
        except TimeoutError:
            if attempt:
                raise
    assert result[0].successful
    assert values == {'time_constant_s': 0.5}
    assert _stop_with(proc, signal.SIGTERM) == 0


def test_out_of_range_parameter_is_one_line_naming_the_node(graph):
    """``-p i2c_bus:=-1``: exit 1, one FATAL line from [imu_driver], no rclpy traceback."""
    proc = graph.start('imu_driver', {'i2c_bus': -1})
    assert proc.wait_exit(timeout=20.0) == 1
    lines = [line for line in proc.output().splitlines() if line.strip()]
    assert len(lines) == 1, lines
    assert '[FATAL]' in lines[0] and '[imu_driver]' in lines[0]
    assert 'i2c_bus: -1 is below the minimum 0' in lines[0]


def test_unknown_executor_is_refused_in_one_line(graph, monkeypatch):
    """A misspelt ACCELCAL_EXECUTOR names the executable and the allowed values."""
    monkeypatch.setenv('ACCELCAL_EXECUTOR', 'fast')
    proc = graph.start('imu_driver', {'backend': 'sim'})
    assert proc.wait_exit(timeout=20.0) == 1
    out = proc.output()
    assert 'Traceback' not in out and '[imu_driver]' in out
    assert 'use one of events, single, multi' in out


def test_fatal_start_up_error_reaches_rosout(graph, monkeypatch):
    """
    An error after the node exists is logged through its logger, so /rosout has it.

    The node lingers until a /rosout reader is matched, at most ACCELCAL_ROSOUT_WAIT_S
    (3 s by default, set long here: discovering a new process can take longer than 3 s on a
    loaded machine, and this test is about the line, not about the default's length).
    """
    monkeypatch.setenv('ACCELCAL_ROSOUT_WAIT_S', '30')
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                     durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
    rosout = graph.collect(Log, '/rosout', qos)
    for attempt in range(2):
        proc = graph.start('imu_driver', {'backend': 'replay'}, name=f'replay_{attempt}')
        assert proc.wait_exit(timeout=45.0) == 1  # replay without a file
        assert 'needs replay.file' in proc.output()
        try:
            rosout.wait_for(1, timeout=15.0)
            break
        except TimeoutError:
            continue
    msgs, _ = rosout.snapshot()
    fatal = [m for m in msgs if m.name == 'imu_driver' and m.level == Log.FATAL]
    assert fatal and 'needs replay.file' in fatal[0].msg
