"""
Graph tests: every node's dropped messages go through its one DropCounter.

For each node that subscribes (attitude, calibration, stitcher with its levelled views,
p2p, lidar_calibration, cloud_assembler; rig_calibration in test_drops_graph.py) a burst
of one representative malformed message is sent until ``/diagnostics`` counts at least
``BURST`` of its kind under ``<node>: dropped messages``; the log then holds the reason
once per throttle period (``1 + elapsed // 10 s`` at most, whatever the load), and the
node goes on working. imu_driver, calibration_frames and the scanner simulation
subscribe to nothing: they have no message to drop.
"""
import math
import time

from accelcal_ros.camera.rig import ring_rig, save_rig
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA
from accelcal_ros.rosutil.drops import THROTTLE_S
from graph_harness.graph import newest_status_values
import pytest

pytestmark = pytest.mark.graph

BURST = 5
"""Dropped messages of a kind the burst reaches before the log is checked."""
TIMEOUT_S = 60.0
"""Longest wait for a burst to be counted (node start-up and discovery on a loaded host)."""


def _dropped(diag, node):
    """Return the newest ``<node>: dropped messages`` values seen on /diagnostics."""
    return newest_status_values(diag, f'{node}: dropped messages')


def _burst(proc, diag, node, kind, send, fragment, count=BURST):
    """Send until ``kind`` is counted ``count`` times; check the throttled log; the values."""
    start = time.monotonic()
    deadline = start + TIMEOUT_S
    values = {}
    while time.monotonic() < deadline:
        values = _dropped(diag, node)
        if int(values.get(f'{kind}_dropped', 0)) >= count:
            break
        send()
        time.sleep(0.05)
    assert int(values.get(f'{kind}_dropped', 0)) >= count, (values, proc.output())
    assert fragment in values[f'{kind}_last_reason'], values
    elapsed = time.monotonic() - start
    lines = proc.output().count(fragment)
    # one line per kind per THROTTLE_S, however many were dropped (and however slow)
    assert 1 <= lines <= 1 + int(elapsed // THROTTLE_S), (lines, elapsed, proc.output())
    assert f'({kind} dropped so far: ' in proc.output()
    assert proc.proc.poll() is None, proc.output()
    return values


def _alive(graph, node, name):
    """Check that the node still answers (its executor is not stuck): a parameter read."""
    assert graph.get_parameters(node, [name], timeout=30.0)


def _imu(ax, ay, az, stamp_s=None):
    from accelcal_ros.rosutil.stamps import seconds_to_stamp
    from builtin_interfaces.msg import Time
    from sensor_msgs.msg import Imu

    msg = Imu()
    msg.header.frame_id = 'imu_link'
    msg.header.stamp = seconds_to_stamp(time.time() if stamp_s is None else stamp_s, Time)
    msg.linear_acceleration.x, msg.linear_acceleration.y = ax, ay
    msg.linear_acceleration.z = az
    msg.angular_velocity_covariance[0] = -1.0
    return msg


def test_attitude_counts_nan_samples_and_goes_on(graph):
    """Samples with NaN: kind imu_nan (and skipped_nan of ``attitude: tilt``); then a tilt."""
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Vector3Stamped
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Imu

    proc = graph.start('attitude')
    diag = graph.collect(DiagnosticArray, '/diagnostics', 50)
    attitude = graph.collect(Vector3Stamped, 'attitude')
    pub = graph.node.create_publisher(Imu, 'imu/data_raw', qos_profile_sensor_data)
    _burst(proc, diag, 'attitude', 'imu_nan', lambda: pub.publish(_imu(math.nan, 0.0, 9.8)),
           'sample skipped (NaN')
    deadline = time.monotonic() + TIMEOUT_S
    while not attitude.snapshot()[0] and time.monotonic() < deadline:
        pub.publish(_imu(0.0, 0.0, 9.80665))
        time.sleep(0.05)
    assert attitude.snapshot()[0], proc.output()
    tilt = {}
    while time.monotonic() < deadline and int(tilt.get('skipped_nan', 0)) < BURST:
        for msg in diag.snapshot()[0]:
            for status in msg.status:
                if status.name == 'attitude: tilt':
                    tilt = {kv.key: kv.value for kv in status.values}
        time.sleep(0.1)
    assert int(tilt['skipped_nan']) >= BURST, tilt   # the older key, read from the counter


def test_calibration_counts_nan_samples_in_a_session(graph, tmp_path):
    """Within a session a NaN sample is kind imu_nan; the session goes on (cancel works)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Imu
    from std_srvs.srv import Trigger

    proc = graph.start('calibration', {'output_file': str(tmp_path / 'cal.yaml'),
                                       'attitude_node': ''})
    assert graph.call(Trigger, 'calibration/start', timeout=30.0).success
    diag = graph.collect(DiagnosticArray, '/diagnostics', 50)
    pub = graph.node.create_publisher(Imu, 'imu/data_raw', qos_profile_sensor_data)
    _burst(proc, diag, 'calibration', 'imu_nan',
           lambda: pub.publish(_imu(math.nan, 0.0, 9.8)), 'sample with NaN or infinity')
    assert graph.call(Trigger, 'calibration/cancel', timeout=30.0).success


def test_stitcher_counts_bad_frames_attitudes_and_steers(graph, tmp_path):
    """Wrong-size frames, absurd attitudes, a NaN steer of a view: each kind counted."""
    from accelcal_ros.rosutil.images import array_to_image_msg
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Vector3Stamped
    import numpy as np
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image

    save_rig(tmp_path / 'rig.yaml', ring_rig(2, 64, 48, 55.0, 45.0,
                                             imu_to_camera=DEFAULT_IMU_TO_CAMERA))
    proc = graph.start('stitcher', params={'rig_file': str(tmp_path / 'rig.yaml'),
                                           'width': 180, 'height': 120,
                                           'image_reliability': 'best_effort',
                                           'roi_views': ['front']})
    diag = graph.collect(DiagnosticArray, '/diagnostics', 50)
    cam = graph.node.create_publisher(Image, 'cam0/image_raw', qos_profile_sensor_data)
    wrong = array_to_image_msg(np.zeros((10, 10, 3), np.uint8), 'bgr8', Image)
    _burst(proc, diag, 'stitcher', 'cam0_frames', lambda: cam.publish(wrong),
           'frame rejected: ')
    att = graph.node.create_publisher(Vector3Stamped, 'attitude', qos_profile_sensor_data)
    bad = Vector3Stamped()
    bad.vector.x = 1e300
    values = _burst(proc, diag, 'stitcher', 'attitudes', lambda: att.publish(bad),
                    'attitude rejected: ')
    assert int(values['cam0_frames_dropped']) >= BURST   # every kind in one status
    steer = graph.node.create_publisher(Vector3Stamped, 'roi/front/steer', 10)
    nan = Vector3Stamped()
    nan.vector.x = float('nan')
    _burst(proc, diag, 'stitcher', 'roi_steer', lambda: steer.publish(nan),
           'roi/front/steer rejected: ')
    _alive(graph, 'stitcher', 'sync_tolerance_s')


def test_p2p_counts_bad_encodings_and_attitudes(graph):
    """An image in an unsupported encoding (kind images), pitch 4 rad (attitudes)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Vector3Stamped
    from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Image

    proc = graph.start('p2p', params={'emitters': [-0.4, 0.0, 0.0, 0.4, 0.0, 0.0]})
    diag = graph.collect(DiagnosticArray, '/diagnostics', 50)
    image = graph.node.create_publisher(
        Image, 'image', QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE))
    bad = Image(height=2, width=2, encoding='32SC4', step=32, data=b'\x00' * 64)
    _burst(proc, diag, 'p2p', 'images', lambda: image.publish(bad), 'image rejected: ')
    att = graph.node.create_publisher(Vector3Stamped, 'attitude', qos_profile_sensor_data)
    pitch4 = Vector3Stamped()
    pitch4.vector.y = 4.0
    _burst(proc, diag, 'p2p', 'attitudes', lambda: att.publish(pitch4), 'attitude rejected: ')
    _alive(graph, 'p2p', 'threshold')


def test_lidar_calibration_counts_imu_stamps_going_backwards(graph, tmp_path):
    """A sample not after the previous one (same stamp again): imu_samples_out_of_order."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Imu
    from std_srvs.srv import Trigger

    proc = graph.start('lidar_calibration', {'output_file': str(tmp_path / 'bs.yaml')})
    assert graph.call(Trigger, 'lidar_calibration/start', timeout=30.0).success
    diag = graph.collect(DiagnosticArray, '/diagnostics', 50)
    pub = graph.node.create_publisher(Imu, 'imu/data_raw', qos_profile_sensor_data)
    stuck = _imu(0.0, 0.0, 9.80665, stamp_s=1000.0)   # every copy after the first: backwards
    _burst(proc, diag, 'lidar_calibration', 'imu_samples_out_of_order',
           lambda: pub.publish(stuck), 'IMU stamp not after the previous one')
    assert graph.call(Trigger, 'lidar_calibration/cancel', timeout=30.0).success


def test_cloud_assembler_counts_rejected_odometry(graph, tmp_path):
    """Odometry with a NaN position (kind odometry); the save service still answers."""
    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.msg import Odometry
    from std_srvs.srv import Trigger

    proc = graph.start('cloud_assembler', {'output_file': str(tmp_path / 'map.ply')})
    diag = graph.collect(DiagnosticArray, '/diagnostics', 50)
    pub = graph.node.create_publisher(Odometry, 'odom', 200)
    bad = Odometry()
    bad.header.frame_id = 'map'
    bad.pose.pose.position.x = float('nan')
    bad.pose.pose.orientation.w = 1.0
    _burst(proc, diag, 'cloud_assembler', 'odometry', lambda: pub.publish(bad),
           'odometry rejected: ')
    graph.call(Trigger, 'cloud_assembler/save', timeout=30.0)   # answers (empty cloud)
    assert proc.proc.poll() is None, proc.output()


def test_attitude_skips_unstamped_and_late_samples_and_restarts_after_a_jump_back(graph):
    """
    Skip unstamped and late samples; restart the estimate when the stamps jump back.

    Stamp 0 (imu_unstamped) and a repeated stamp (imu_out_of_order) are skipped; stamps
    jumping back by a second or more (a bag played again: imu_time_jump) restart the
    estimate there. Before, such samples were published as they came, and after a jump back
    the filter ran on a frozen clock: a tilted sensor's roll crawled from 0.19 to 13.9 deg.
    """
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Vector3Stamped
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Imu

    proc = graph.start('attitude')
    diag = graph.collect(DiagnosticArray, '/diagnostics', 50)
    attitude = graph.collect(Vector3Stamped, 'attitude')
    pub = graph.node.create_publisher(Imu, 'imu/data_raw', qos_profile_sensor_data)
    _burst(proc, diag, 'attitude', 'imu_unstamped', lambda: pub.publish(
        _imu(0.0, 0.0, 9.80665, stamp_s=0.0)), 'header stamp 0 skipped')
    stamp = 1000.0   # until the output is seen (discovery): stamps that increase
    deadline = time.monotonic() + TIMEOUT_S
    while not attitude.snapshot()[0] and time.monotonic() < deadline:
        stamp += 0.01
        pub.publish(_imu(0.0, 0.0, 9.80665, stamp_s=stamp))
        time.sleep(0.05)
    assert all(m.header.stamp.sec >= 1000 for m in attitude.snapshot()[0]), \
        'a sample stamped 0 was published'
    stuck = _imu(0.0, 0.0, 9.80665, stamp_s=2000.0)   # every copy after the first: late
    _burst(proc, diag, 'attitude', 'imu_out_of_order', lambda: pub.publish(stuck),
           'not after the previous one')
    time.sleep(1.0)   # what was published has arrived
    published = [m for m in attitude.snapshot()[0] if m.header.stamp.sec == 2000]
    assert len(published) == 1, len(published)
    g = 9.80665
    roll = math.radians(-20.0)   # level before the jump, rolled -20 deg after it
    stamp = 100.0
    values = {}
    deadline = time.monotonic() + TIMEOUT_S
    while time.monotonic() < deadline and int(values.get('imu_time_jump_dropped', 0)) < 1:
        values = _dropped(diag, 'attitude')
        stamp += 0.01
        pub.publish(_imu(0.0, g * math.sin(roll), g * math.cos(roll), stamp_s=stamp))
        time.sleep(0.05)
    assert 'jumped back by 1899.99' in values['imu_time_jump_last_reason'], values
    after = [m for m in attitude.snapshot()[0] if m.header.stamp.sec < 2000]
    assert after, proc.output()
    first = min(after, key=lambda m: (m.header.stamp.sec, m.header.stamp.nanosec))
    assert math.degrees(first.vector.x) == pytest.approx(-20.0, abs=0.5), first


def test_calibration_nodes_say_when_no_imu_sample_arrived(graph, tmp_path):
    """
    Name the topic when a capture finds no IMU sample; count those skipped for stamps.

    All three nodes said "moving" / "not still" before.
    """
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Imu
    from std_srvs.srv import Trigger

    nodes = {'calibration': {'output_file': str(tmp_path / 'cal.yaml'), 'attitude_node': ''},
             'lidar_calibration': {'output_file': str(tmp_path / 'bs.yaml')},
             'rig_calibration': {'output_file': str(tmp_path / 'rig.yaml'),
                                 'capture_dir': str(tmp_path / 'cap'), 'cameras': ['cam0']}}
    procs = {node: graph.start(node, params) for node, params in nodes.items()}
    for node, proc in procs.items():
        assert graph.call(Trigger, f'{node}/start', timeout=30.0).success, proc.output()
        answer = graph.call(Trigger, f'{node}/capture', timeout=30.0)
        assert not answer.success
        assert answer.message.startswith('no usable sample on /imu/data_raw since start: is '
                                         'the driver running'), (node, answer.message)
    pub = graph.node.create_publisher(Imu, 'imu/data_raw', qos_profile_sensor_data)
    from diagnostic_msgs.msg import DiagnosticArray

    diag = graph.collect(DiagnosticArray, '/diagnostics', 50)
    _burst(procs['calibration'], diag, 'calibration', 'imu_unstamped', lambda: pub.publish(
        _imu(0.0, 0.0, 9.80665, stamp_s=0.0)), 'header stamp 0 skipped')
    answer = graph.call(Trigger, 'calibration/capture', timeout=30.0)
    assert not answer.success and 'skipped for their header stamps' in answer.message, \
        answer.message
