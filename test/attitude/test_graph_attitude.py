"""Graph test: the attitude node with good and bad calibrations and bad samples."""
import math
import time

from accelcal_ros.calibration.coverage import recommended_directions
from accelcal_ros.calibration.ellipsoid_fit import fit_ellipsoid
from accelcal_ros.frames import specific_force_from_roll_pitch
from accelcal_ros.sensor.calibration_file import save_calibration
from accelcal_ros.sensor.model import paper_a_model
import numpy as np
import pytest

G = 9.80665
TRUTH = paper_a_model(500)


def _publish(graph, pub, raw_g, stamp):
    from sensor_msgs.msg import Imu

    msg = Imu()
    msg.header.frame_id = 'imu_link'
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp, 0
    msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = (
        float(v * G) for v in raw_g)
    pub.publish(msg)


def _latest_for(collector, stamp, timeout=30.0):
    from accelcal_ros.rosutil.stamps import stamp_to_seconds

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for msg in reversed(collector.snapshot()[0]):
            if stamp_to_seconds(msg.header.stamp) == stamp:
                return msg
        time.sleep(0.05)
    return None


@pytest.mark.graph
def test_attitude_node_calibration_files_and_bad_input(graph, tmp_path):
    from geometry_msgs.msg import Vector3Stamped
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Imu

    good = tmp_path / 'good.yaml'
    save_calibration(good, fit_ellipsoid(TRUTH.distort(recommended_directions(14)),
                                         np.full((14, 3), 2e-4)))
    truncated = tmp_path / 'truncated.yaml'
    truncated.write_text(good.read_text()[:60])
    proc = graph.start('attitude', params={'calibration_file': str(tmp_path / 'nope.yaml')})
    pub = graph.node.create_publisher(Imu, 'imu/data_raw', qos_profile_sensor_data)
    attitude = graph.collect(Vector3Stamped, 'attitude')
    imu = graph.collect(Imu, 'imu/data')
    roll, pitch = math.radians(25.0), math.radians(-40.0)
    raw = TRUTH.distort(specific_force_from_roll_pitch(roll, pitch))

    # Missing file at start-up: a warning (not an error), uncalibrated until it appears.
    # until the node is up and discovered (a loaded machine: tens of seconds); stamps 1..
    msg, stamp = None, 0
    deadline = time.monotonic() + 60.0
    while msg is None and time.monotonic() < deadline:
        stamp = min(stamp + 1, 38)   # 40 and on: the next step's stamps
        _publish(graph, pub, raw, stamp)
        msg = _latest_for(attitude, stamp, timeout=0.3)
    assert msg is not None, proc.output()
    assert abs(msg.vector.y - pitch) > math.radians(1.0)
    assert 'nope.yaml does not exist yet' in proc.output()
    assert 'ERROR' not in proc.output()
    (tmp_path / 'nope.yaml').write_text(good.read_text())   # the calibration is run
    stamp = 39
    deadline = time.monotonic() + 60.0   # the file is looked for every second
    while time.monotonic() < deadline and stamp < 99:
        stamp += 1
        _publish(graph, pub, raw, stamp)
        msg = _latest_for(attitude, stamp, timeout=0.3)
        if msg is not None and msg.vector.y == pytest.approx(pitch, abs=1e-6):
            break
    assert msg.vector.y == pytest.approx(pitch, abs=1e-6), proc.output()
    assert 'loaded full calibration from' in proc.output()

    # A good file at run time is applied.
    result = graph.set_parameters('attitude', {'calibration_file': str(good)})
    assert result[0].successful, result[0].reason
    _publish(graph, pub, raw, 100)
    msg = _latest_for(attitude, 100)
    assert msg.vector.x == pytest.approx(roll, abs=1e-6)
    assert msg.vector.y == pytest.approx(pitch, abs=1e-6)
    out = _latest_for(imu, 100)
    q = np.array([out.orientation.x, out.orientation.y, out.orientation.z, out.orientation.w])
    assert np.linalg.norm(q) == pytest.approx(1.0)
    assert 0.0 < out.orientation_covariance[0] < 1e-3 and out.orientation_covariance[8] >= 1e3

    # Truncated / missing files and wrong shapes are rejected; the last good one is kept.
    for bad in ({'calibration_file': str(truncated)},
                {'calibration_file': str(tmp_path / 'gone.yaml')},
                {'calibration.scale': [1.0, 1.0]}):
        result = graph.set_parameters('attitude', bad)
        assert not result[0].successful and result[0].reason
    _publish(graph, pub, raw, 101)
    msg = _latest_for(attitude, 101)
    assert msg.vector.y == pytest.approx(pitch, abs=1e-6)

    # An empty calibration_file means the calibration.* values (here: none).
    result = graph.set_parameters('attitude', {'calibration_file': ''})
    assert result[0].successful, result[0].reason
    _publish(graph, pub, raw, 107)
    msg = _latest_for(attitude, 107)
    assert abs(msg.vector.y - pitch) > math.radians(1.0)
    result = graph.set_parameters('attitude', {'calibration_file': str(good)})
    assert result[0].successful, result[0].reason

    # Impossible samples are skipped (no output, node alive, counted in /diagnostics,
    # logged once in 10 s); pitch +-90 gives no NaN.
    from diagnostic_msgs.msg import DiagnosticArray

    diagnostics = graph.collect(DiagnosticArray, '/diagnostics')
    _publish(graph, pub, [math.nan, 0.0, 1.0], 102)
    _publish(graph, pub, [0.0, 0.0, 0.0], 104)
    _publish(graph, pub, [1e300, 0.0, 0.0], 105)
    _publish(graph, pub, [0.0, 1e300 / G, 1.0], 106)
    vertical = TRUTH.distort(specific_force_from_roll_pitch(0.0, math.radians(90.0)))
    _publish(graph, pub, vertical, 103)
    msg = _latest_for(attitude, 103)
    assert msg is not None and math.isfinite(msg.vector.x)
    assert msg.vector.y == pytest.approx(math.pi / 2, abs=1e-6)
    for stamp in (102, 104, 105, 106):
        assert _latest_for(attitude, stamp, timeout=0.2) is None
        assert _latest_for(imu, stamp, timeout=0.01) is None
    out = _latest_for(imu, 103)
    assert all(math.isfinite(v) for v in out.orientation_covariance)
    assert proc.proc.poll() is None
    out = proc.output()
    for reason in ('NaN', 'zero', 'out of range'):  # one line per kind (throttled, 10 s)
        assert out.count(f'sample skipped ({reason}:') == 1, out
    counts = {}
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline and counts.get('skipped_out_of_range') != '2':
        time.sleep(0.2)
        for array in diagnostics.snapshot()[0]:
            for status in array.status:
                if status.name == 'attitude: tilt':
                    counts = {kv.key: kv.value for kv in status.values}
    assert counts.get('skipped_nan') == '1' and counts.get('skipped_zero') == '1'
    assert counts.get('skipped_out_of_range') == '2' and counts.get('calibrated') == 'true'
