"""Graph test: the ``calibration`` node's coverage markers during a session."""
import time

from accelcal_ros.calibration.coverage import missing_directions
from accelcal_ros.rosutil.stamps import seconds_to_stamp
from builtin_interfaces.msg import Time
import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu

G = 9.80665
POSES = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.6, 0.6, 0.53]])


def _imu(t, accel):
    msg = Imu()
    msg.header.stamp = seconds_to_stamp(t, Time)
    msg.header.frame_id = 'imu_link'
    msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = \
        (float(v) for v in accel)
    msg.angular_velocity_covariance[0] = -1.0
    return msg


def _status_values(msg):
    return {kv.key: kv.value for kv in msg.values}


@pytest.mark.graph
def test_one_marker_per_capture_at_the_captured_directions(graph):
    """Still dwells at known specific forces: captured markers = those directions, in order."""
    from diagnostic_msgs.msg import DiagnosticStatus
    from std_srvs.srv import Trigger
    from visualization_msgs.msg import MarkerArray

    proc = graph.start('calibration', params={'min_still_s': 0.6})
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    markers = graph.collect(MarkerArray, 'calibration/coverage_markers', qos=latched)
    status = graph.collect(DiagnosticStatus, 'calibration/status', qos=latched)
    assert graph.call(Trigger, 'calibration/start', timeout=20.0).success, proc.output()
    pub = graph.node.create_publisher(Imu, 'imu/data_raw', qos_profile_sensor_data)
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline and not pub.get_subscription_count():
        time.sleep(0.05)
    rng = np.random.default_rng(1)
    t_sim, k = 100.0, 0
    units = POSES / np.linalg.norm(POSES, axis=1)[:, None]
    start = time.monotonic()
    for unit in units:
        moving = rng.normal(0.0, 0.4 * G, (40, 3)) + unit * G
        for accel in list(moving) + [unit * G] * 150:           # 0.4 s moving, 1.5 s still
            pub.publish(_imu(t_sim + 0.01 * k, accel))
            k += 1
            lag = 0.01 * k - (time.monotonic() - start)
            if lag > 0:
                time.sleep(lag)
    for _ in range(40):                                          # end the last dwell
        pub.publish(_imu(t_sim + 0.01 * k, rng.normal(0.0, 0.4 * G, 3)))
        k += 1
        time.sleep(0.01)

    def captured(array):
        return [m for m in array.markers if m.ns == 'captured']
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline:
        arrays = markers.snapshot()[0]
        if arrays and len(captured(arrays[-1])) >= len(POSES):
            break
        time.sleep(0.1)
    latest = markers.snapshot()[0][-1]
    spheres = captured(latest)
    assert len(spheres) == len(POSES), proc.output()
    got = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z] for m in spheres])
    assert [m.id for m in spheres] == list(range(len(POSES)))
    assert np.abs(got - units).max() < 1e-9
    assert latest.markers[0].action == latest.markers[0].DELETEALL
    assert all(m.header.frame_id == 'imu_link' for m in latest.markers)
    missing = [m for m in latest.markers if m.ns == 'missing']
    assert len(missing) == len(missing_directions(units, 40.0)) > 0
    (arrow,) = [m for m in latest.markers if m.ns == 'next']
    hint = _status_values(status.snapshot()[0][-1])['hint']
    assert hint.split('; ')[0] == arrow.text
    tip = np.array([arrow.points[1].x, arrow.points[1].y, arrow.points[1].z])
    assert abs(np.linalg.norm(tip) - 1.0) < 1e-9
