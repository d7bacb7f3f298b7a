"""
Graph tests: imu_driver (sim, still rig) -> attitude -> the stitcher's frame-set choice.

The attitude a 25 fps frame set is stitched with (the stitcher's own
:class:`~accelcal_ros.panorama.frame_sets.FrameSetPolicy`, fed with the attitude node's
messages and frames stamped 40 ms apart) must keep the horizon within 0.5 px rms from one
frame to the next at f = 1100 px, at 100 and 800 Hz with the defaults. Then the gyro and
odometry inputs of the node, good and bad.
"""
import math
import time

from accelcal_ros.frames import specific_force_from_roll_pitch
from accelcal_ros.panorama.frame_sets import FrameSetPolicy
from accelcal_ros.sensor.model import PAPER_K500_BIAS, PAPER_K500_SCALE
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3Stamped
import numpy as np
import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu

pytestmark = pytest.mark.graph
G = 9.80665
FOCAL_PX = 1100.0


def _stamp(msg):
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


@pytest.mark.parametrize('rate', [100.0, 800.0])
def test_still_rig_horizon_is_steady_between_frame_sets(graph, rate):
    deep = QoSProfile(depth=5000, reliability=ReliabilityPolicy.BEST_EFFORT)
    attitude = graph.collect(Vector3Stamped, 'attitude', deep)
    graph.start('imu_driver', {'backend': 'sim', 'rate_hz': rate, 'seed': 7,
                               'sim.poses_deg': [4.0, -7.0], 'sim.dwell_s': 3600.0})
    proc = graph.start('attitude', {'calibration.scale': list(PAPER_K500_SCALE),
                                    'calibration.bias': list(PAPER_K500_BIAS),
                                    'calibration.model': 'diagonal'})
    attitude.wait_for(int(rate), timeout=30.0)
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline:   # 6 s of attitude after 2 s of settling
        msgs, _ = attitude.snapshot()
        stamps = [_stamp(m) for m in msgs]
        if stamps and stamps[-1] - stamps[0] > 8.0:
            break
        time.sleep(0.2)
    msgs, _ = attitude.snapshot()
    assert msgs, proc.output()
    start = _stamp(msgs[0]) + 2.0
    policy = FrameSetPolicy(['cam0'], {'sync_tolerance_s': 0.01, 'stale_timeout_s': 1e9,
                                       'attitude_tolerance_s': 0.1, 'attitude_wait_s': 0.0})
    chosen = []
    fed = 0
    for stamp in np.arange(start, _stamp(msgs[-1]) - 0.05, 0.04):
        # the attitudes as they would arrive: up to a little after the frame
        while fed < len(msgs) and _stamp(msgs[fed]) <= stamp + 0.02:
            m = msgs[fed]
            policy.add_attitude(_stamp(m), m.vector.x, m.vector.y, float(stamp))
            fed += 1
        policy.add_frame(0, float(stamp), None, float(stamp))
        frame_set = policy.poll(float(stamp))
        if frame_set is not None:
            chosen.append((frame_set.roll_rad, frame_set.pitch_rad))
    chosen = np.array(chosen)
    assert len(chosen) > 100
    jitter = FOCAL_PX * math.sqrt(np.mean(np.sum(np.diff(chosen, axis=0) ** 2, axis=1)))
    assert jitter <= 0.5, f'{jitter:.2f} px at {rate} Hz'
    assert np.degrees(chosen[:, 0]).mean() == pytest.approx(4.0, abs=0.1)
    assert np.degrees(chosen[:, 1]).mean() == pytest.approx(-7.0, abs=0.1)


def _imu(stamp_s, force_g, gyro=None, frame='imu_link'):
    msg = Imu()
    msg.header.frame_id = frame
    sec = int(stamp_s)
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, int(round((stamp_s - sec) * 1e9))
    a = msg.linear_acceleration
    a.x, a.y, a.z = (float(v * G) for v in force_g)
    if gyro is None:
        msg.angular_velocity_covariance[0] = -1.0
    else:
        w = msg.angular_velocity
        w.x, w.y, w.z = (float(v) for v in gyro)
        msg.angular_velocity_covariance[0] = 1e-4
    return msg


def _diag_values(diagnostics, timeout=30.0, want=None):
    deadline = time.monotonic() + timeout
    values, message = {}, ''
    while time.monotonic() < deadline:
        arrays, _ = diagnostics.snapshot()
        for array in reversed(arrays):
            for status in array.status:
                if status.name == 'attitude: tilt':
                    values = {kv.key: kv.value for kv in status.values}
                    message = status.message
                    if want is None or want(values, message):
                        return values, message
                    break
            else:
                continue
            break
        time.sleep(0.2)
    return values, message


def test_attitude_node_gyro_and_odometry_inputs(graph):
    from nav_msgs.msg import Odometry
    from rclpy.qos import qos_profile_sensor_data

    out = graph.collect(Imu, 'imu/data', QoSProfile(depth=2000,
                                                    reliability=ReliabilityPolicy.BEST_EFFORT))
    diagnostics = graph.collect(DiagnosticArray, '/diagnostics', 10)
    proc = graph.start('attitude', {'gyro_topic': 'gyro', 'odometry_topic': 'odom',
                                    'platform_accel_g': 0.3,
                                    'calibration.bias': [0.0, 0.0, 0.001]})
    pub = graph.node.create_publisher(Imu, 'imu/data_raw', qos_profile_sensor_data)
    gyro_pub = graph.node.create_publisher(Imu, 'gyro', qos_profile_sensor_data)
    odo_pub = graph.node.create_publisher(Odometry, 'odom', qos_profile_sensor_data)
    force = specific_force_from_roll_pitch(0.1, -0.05) + np.array([0.0, 0.0, 0.001])

    # accelerometer only on a platform that may accelerate: WARN, covariance says so
    t = 100.0
    deadline = time.monotonic() + 20.0
    while not out.snapshot()[0] and time.monotonic() < deadline:   # discovery
        pub.publish(_imu(t, force))
        t += 0.01
        time.sleep(0.05)
    for _ in range(60):
        pub.publish(_imu(t, force))
        t += 0.01
        time.sleep(0.005)
    values, message = _diag_values(diagnostics, want=lambda v, m: 'moving platform' in m)
    assert 'valid only while it does not accelerate' in message, (values, message)
    msgs = out.wait_for(10, timeout=30.0)
    assert msgs[-1].orientation_covariance[0] > math.atan(0.3) ** 2 * 0.99

    # angular velocity inside imu/data_raw: used, bias learnt while still
    for _ in range(300):
        pub.publish(_imu(t, force, (0.01, -0.02, 0.005)))
        t += 0.01
        time.sleep(0.003)
    values, message = _diag_values(diagnostics, want=lambda v, m: v.get('mode') == 'gyro-aided')
    assert values.get('mode') == 'gyro-aided', (values, message, proc.output())
    assert values['gyro_bias_known'] == 'true'
    msgs, _ = out.snapshot()
    assert msgs[-1].angular_velocity_covariance[0] > 0
    assert abs(msgs[-1].angular_velocity.y) < 0.01   # bias removed

    # NaN gyro: counted, the node goes on
    for _ in range(20):
        pub.publish(_imu(t, force, (math.nan, 0.0, 0.0)))
        t += 0.01
    values, _ = _diag_values(diagnostics, want=lambda v, m: int(v.get('gyro_nan', 0)) > 0)
    assert int(values['gyro_nan']) > 0

    # a gyro topic in another frame without gyro_rotation: refused with the reason
    for _ in range(30):
        gyro_pub.publish(_imu(t, force, (0.0, 0.0, 0.0), frame='gyro_link'))
        pub.publish(_imu(t, force))
        t += 0.01
        time.sleep(0.003)
    values, message = _diag_values(diagnostics, want=lambda v, m: 'gyro_link' in m)
    assert 'no gyro_rotation relates them' in message, (values, message)

    # odometry running backwards in time: said once, counted (a step back of a second or
    # more is the clock jumping back, a bag played again: the aid restarts, not counted)
    for stamp in (t, t + 0.02, t - 0.5, t - 5.0):
        odo = Odometry()
        sec = int(stamp)
        odo.header.stamp.sec, odo.header.stamp.nanosec = sec, int((stamp - sec) * 1e9)
        odo_pub.publish(odo)
        time.sleep(0.05)
    values, _ = _diag_values(diagnostics, want=lambda v, m: 'bad_odometry' in v)
    assert values.get('bad_odometry') == '1', values
    deadline = time.monotonic() + 30.0
    while 'backwards in time' not in proc.output() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert 'backwards in time' in proc.output()
    assert 'Traceback' not in proc.output()

    # the lever arm (odometry and gyro path), set at run time: a bad one refused with the
    # reason, a good one taken; the node goes on
    result = graph.set_parameters('attitude', {'lever_arm_m': [1.0, 0.3]})
    assert not result[0].successful and 'lever_arm_m' in result[0].reason, result[0].reason
    result = graph.set_parameters('attitude', {'lever_arm_m': [1.0, 0.3, 0.8]})
    assert result[0].successful, result[0].reason
    count = len(out.snapshot()[0])
    deadline = time.monotonic() + 30.0
    while len(out.snapshot()[0]) < count + 5 and time.monotonic() < deadline:
        pub.publish(_imu(t, force, (0.01, -0.02, 0.005)))
        t += 0.01
        time.sleep(0.01)
    assert len(out.snapshot()[0]) >= count + 5, proc.output()
    assert 'Traceback' not in proc.output()
