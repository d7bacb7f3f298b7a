"""
Graph test: dropped messages are counted in /diagnostics and logged (throttled).

``lidar_calibration`` gets PointCloud2 messages without x/y/z fields and IMU samples with
NaN; ``rig_calibration`` gets an image of an unsupported encoding. Each kind's count is
in a ``<node>: dropped messages`` status; the log has one line per kind (throttled),
not one per message. ``output_file`` cannot be set to empty at run time.
"""
import time

from graph_harness.graph import newest_status_values
import pytest

pytestmark = pytest.mark.graph


def _dropped(diag, node):
    """Return the newest ``<node>: dropped messages`` values seen on /diagnostics."""
    return newest_status_values(diag, f'{node}: dropped messages')


def _wait_for(diag, node, key, count, send, timeout=30.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if int(_dropped(diag, node).get(key, 0)) >= count:
            return _dropped(diag, node)
        send()
        time.sleep(0.2)
    raise AssertionError(f'{node}: {key} not counted; saw {_dropped(diag, node)}')


def test_lidar_calibration_counts_and_logs_dropped_clouds_and_samples(graph, tmp_path):
    """Malformed clouds and NaN samples: counted, one log line per kind, node alive."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Imu, PointCloud2, PointField

    from std_srvs.srv import Trigger

    proc = graph.start('lidar_calibration', {'output_file': str(tmp_path / 'bs.yaml')})
    # outside a session the node reads nothing; within one a malformed message is a drop
    assert graph.call(Trigger, 'lidar_calibration/start', timeout=20.0).success
    diag = graph.collect(DiagnosticArray, '/diagnostics', 50)
    clouds = graph.node.create_publisher(PointCloud2, 'points', qos_profile_sensor_data)
    imu = graph.node.create_publisher(Imu, 'imu/data_raw', qos_profile_sensor_data)
    bad = PointCloud2(height=1, width=1, point_step=4, row_step=4, data=b'\x00' * 4)
    bad.fields = [PointField(name='intensity', offset=0, datatype=PointField.FLOAT32, count=1)]
    values = _wait_for(diag, 'lidar_calibration', 'clouds_dropped', 5,
                       lambda: clouds.publish(bad))
    assert 'unusable PointCloud2' in values['clouds_last_reason']
    sample = Imu()
    sample.linear_acceleration.x = float('nan')
    _wait_for(diag, 'lidar_calibration', 'imu_samples_dropped', 5, lambda: imu.publish(sample))
    out = proc.output()
    assert out.count('unusable PointCloud2 ignored') == 1, out  # throttled: 10 s
    assert out.count('IMU sample with NaN ignored') == 1, out
    result = graph.set_parameters('lidar_calibration', {'output_file': ''})
    assert not result[0].successful and 'must not be empty' in result[0].reason
    assert proc.proc.poll() is None


def test_rig_calibration_counts_unusable_images_and_refuses_an_empty_output(graph, tmp_path):
    """An image in an unsupported encoding is counted per camera; output_file '' refused."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image

    from std_srvs.srv import Trigger

    proc = graph.start('rig_calibration', {'output_file': str(tmp_path / 'rig.yaml'),
                                           'capture_dir': str(tmp_path / 'cap'),
                                           'cameras': ['cam0']})
    assert graph.call(Trigger, 'rig_calibration/start', timeout=20.0).success
    diag = graph.collect(DiagnosticArray, '/diagnostics', 50)
    pub = graph.node.create_publisher(Image, 'cam0/image_raw', qos_profile_sensor_data)
    image = Image(height=2, width=2, encoding='32SC4', step=32, data=b'\x00' * 64)
    values = _wait_for(diag, 'rig_calibration', 'cam0_images_dropped', 3,
                       lambda: pub.publish(image))
    assert 'unusable image ignored' in values['cam0_images_last_reason']
    result = graph.set_parameters('rig_calibration', {'output_file': ''})
    assert not result[0].successful and 'must not be empty' in result[0].reason
    assert proc.proc.poll() is None
