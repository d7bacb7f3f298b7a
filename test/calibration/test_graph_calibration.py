"""Graph test: driver (sim) + calibration + attitude as processes, as a user runs them."""
import time

from accelcal_ros.calibration.coverage import recommended_directions, roll_pitch_deg_of
from accelcal_ros.driver.sim_truth import dwell_errors_deg
from accelcal_ros.sensor.calibration_file import load_calibration
import numpy as np
import pytest

TRUTH_SCALE = np.array([0.928, 0.909, 0.896])
TRUTH_BIAS = np.array([-0.025, -0.037, -0.056])


def _status_values(msg):
    return {kv.key: kv.value for kv in msg.values}


@pytest.mark.graph
def test_calibrate_in_a_graph_and_attitude_follows(graph, tmp_path):
    from diagnostic_msgs.msg import DiagnosticStatus
    from geometry_msgs.msg import Vector3Stamped
    from std_srvs.srv import Trigger

    poses = roll_pitch_deg_of(recommended_directions(14)).ravel().tolist()
    output = tmp_path / 'calibration.yaml'
    graph.start('imu_driver', params={'backend': 'sim', 'rate_hz': 100.0, 'seed': 2,
                                      'sim.poses_deg': poses, 'sim.dwell_s': 1.0,
                                      'sim.move_s': 0.4})
    graph.start('calibration', params={'output_file': str(output), 'min_still_s': 0.7})
    graph.start('attitude')
    status = graph.collect(DiagnosticStatus, 'calibration/status', 10)
    attitude = graph.collect(Vector3Stamped, 'attitude')
    truth = graph.collect(Vector3Stamped, 'sim/attitude_truth')

    # Services out of order are refused with the reason.
    reply = graph.call(Trigger, 'calibration/finish', timeout=20.0)
    assert not reply.success and 'calibration/start' in reply.message
    assert graph.call(Trigger, 'calibration/start').success
    reply = graph.call(Trigger, 'calibration/start')
    assert not reply.success and 'already running' in reply.message
    # A manual capture either takes the current dwell or says why not.
    reply = graph.call(Trigger, 'calibration/capture')
    assert reply.message.startswith('captured position 0') if reply.success else (
        'moving' in reply.message or 'still for only' in reply.message)

    deadline = time.monotonic() + 45.0
    positions = 0
    while time.monotonic() < deadline and positions < 14:
        time.sleep(0.5)
        messages, _ = status.snapshot()
        if messages:
            positions = int(_status_values(messages[-1]).get('captures', 0))
    assert positions >= 14, f'only {positions} positions captured'
    values = _status_values(status.snapshot()[0][-1])
    assert float(values['coverage_percent']) >= 99.0
    assert 0.0 < float(values['predicted_error_deg']) < 0.1

    before = dwell_errors_deg(attitude.snapshot()[0], truth.snapshot()[0])

    reply = graph.call(Trigger, 'calibration/finish', timeout=20.0)
    assert reply.success, reply.message
    assert str(output) in reply.message
    record = load_calibration(output)
    assert record.model == 'full' and record.data['positions'] >= 14
    np.testing.assert_allclose(record.sensor_model.scale, TRUTH_SCALE, atol=1.5e-3)
    np.testing.assert_allclose(record.sensor_model.bias, TRUTH_BIAS, atol=1.5e-3)
    assert record.predicted_tilt_error_deg < 0.1
    reply = graph.call(Trigger, 'calibration/cancel')
    assert not reply.success and 'no calibration session' in reply.message

    # The attitude node received the calibration through its parameter service.
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline:
        scale = graph.get_parameters('attitude', ['calibration.scale'])['calibration.scale']
        if abs(scale[0] - record.sensor_model.scale[0]) < 1e-9:
            break
        time.sleep(0.2)
    assert scale[0] == pytest.approx(record.sensor_model.scale[0])

    # A late joiner (ros2 topic echo --once) gets the latest status only: once the
    # attitude node's reply has come back (the last status the session publishes).
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline and not any(
            'calibration applied to' in _status_values(m).get('last_event', '')
            for m in status.snapshot()[0]):
        time.sleep(0.1)
    late = graph.collect(DiagnosticStatus, 'calibration/status', QoSProfile(
        depth=10, reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    replayed = late.wait_for(1, timeout=30.0)
    time.sleep(1.0)   # nothing more comes: no session runs (a second one would show)
    replayed = late.snapshot()[0]
    assert len(replayed) == 1, [m.message for m in replayed]
    assert replayed[0].message.startswith('last calibration')
    attitude.clear()
    truth.clear()
    deadline = time.monotonic() + 60.0   # at least one whole dwell, however slow
    after = {}
    while len(after) < 1 and time.monotonic() < deadline:
        time.sleep(0.5)
        after = dwell_errors_deg(attitude.snapshot()[0], truth.snapshot()[0])
    assert len(after) >= 1
    worst_after = max(np.abs(v).max() for v in after.values())
    assert worst_after < 0.15, after
    if before:
        assert max(np.abs(v).max() for v in before.values()) > 1.0  # uncalibrated: degrees
