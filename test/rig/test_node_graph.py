"""Graph test: ``rig_calibration`` as a process, fed rendered camera frames and gravity."""
import os
import time

from accelcal_ros.rig.render import default_truth, imu_samples, plan_poses, Renderer
from accelcal_ros.rosutil.images import array_to_image_msg
from accelcal_ros.rosutil.stamps import seconds_to_stamp
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
import pytest
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image, Imu
from std_msgs.msg import Header
from std_srvs.srv import Trigger


def _imu(t, accel):
    msg = Imu()
    msg.header.stamp = seconds_to_stamp(t, Time)
    msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = \
        (float(v) for v in accel)
    msg.angular_velocity_covariance[0] = -1.0
    return msg


def _publishers(graph, truth):
    """IMU and camera publishers, once the node subscribes to all of them."""
    imu_pub = graph.node.create_publisher(Imu, 'imu/data_raw', qos_profile_sensor_data)
    image_pubs = [graph.node.create_publisher(Image, f'{c}/image_raw', qos_profile_sensor_data)
                  for c in truth.names]
    deadline = time.monotonic() + 15.0
    while time.monotonic() < deadline and not all(
            p.get_subscription_count() for p in [imu_pub] + image_pubs):
        time.sleep(0.05)
    return imu_pub, image_pubs


def _feed(truth, poses, imu_pub, image_pubs, speed=1.0):
    """Per pose: 0.4 s of motion, then 2 s still with a frame set every 0.1 s (100 Hz IMU)."""
    renderer = Renderer(truth)
    rng = np.random.default_rng(0)
    t_sim = 100.0
    for pose in poses:
        images = [renderer.render(pose, i) for i in range(3)]
        samples = imu_samples(truth, pose, rng, duration_s=2.0)
        moving = imu_samples(truth, pose, rng, duration_s=0.4, motion_m_s2=3.0)
        start = time.monotonic()
        for k, a in enumerate(np.vstack([moving['a'], samples['a']])):
            t = t_sim + 0.01 * k
            imu_pub.publish(_imu(t, a))
            if k % 10 == 5:
                for pub, image in zip(image_pubs, images):
                    header = Header(stamp=seconds_to_stamp(t, Time), frame_id='camera')
                    pub.publish(array_to_image_msg(image, 'mono8', Image, header))
            lag = 0.01 * k / speed - (time.monotonic() - start)
            if lag > 0:
                time.sleep(lag)
        t_sim += 0.01 * (k + 1)


@pytest.mark.graph
def test_rig_calibration_node_captures_reports_and_refuses_early_finish(graph, tmp_path):
    """Two still poses captured automatically; status counts views; finish says what to add."""
    truth = default_truth()
    poses = plan_poses(truth, 2)
    capture_dir = tmp_path / 'capture'
    graph.start('rig_calibration', params={
        'cameras': truth.names, 'board': '11x8', 'square_m': 0.025,
        'capture_dir': str(capture_dir), 'output_file': str(tmp_path / 'rig.yaml'),
        'min_still_s': 0.5, 'status_period_s': 0.3})
    status = graph.collect(DiagnosticStatus, 'rig_calibration/status', qos=10)
    started = graph.call(Trigger, 'rig_calibration/start', timeout=20.0)
    assert started.success and str(capture_dir) in started.message, started.message
    imu_pub, image_pubs = _publishers(graph, truth)
    _feed(truth, poses, imu_pub, image_pubs)
    deadline = time.monotonic() + 20.0
    latest = {}
    while time.monotonic() < deadline:
        messages = status.snapshot()[0]
        latest = {kv.key: kv.value for kv in messages[-1].values} if messages else {}
        if int(latest.get('captures', 0)) >= 2:
            break
        time.sleep(0.2)
    assert latest.get('captures') == '2', latest
    sessions = os.listdir(capture_dir)
    assert len(sessions) == 1 and sessions[0].startswith('session_')
    assert latest['capture_dir'] == str(capture_dir / sessions[0])
    assert sorted(os.listdir(capture_dir / sessions[0])) == ['pose00', 'pose01']
    views = [int(latest[f'{c}.views']) for c in truth.names]
    assert views == [sum(i in p.visible for p in poses) for i in range(3)]
    assert 'show' in latest['hint']
    finish = graph.call(Trigger, 'rig_calibration/finish', timeout=60.0)
    assert not finish.success and 'need at least' in finish.message
    assert 'session stays open' in finish.message


@pytest.mark.graph
def test_rig_calibration_finish_publishes_the_rig_on_tf_static(graph, tmp_path):
    """12 poses captured live (400x300); finish writes the rig and publishes it (late joiner)."""
    from accelcal_ros.camera.rig import load_rig
    from accelcal_ros.frame_tree import check_tree, to_ancestor
    from accelcal_ros.rosutil.static_tf import msg_to_transform, STATIC_TF_QOS
    from tf2_msgs.msg import TFMessage

    truth = default_truth(width=400, height=300, focal_px=212.0)
    poses = plan_poses(truth, 12)
    output = tmp_path / 'rig.yaml'
    proc = graph.start('rig_calibration', params={
        'cameras': truth.names, 'board': '11x8', 'square_m': 0.025,
        'capture_dir': str(tmp_path / 'capture'), 'output_file': str(output),
        'min_still_s': 0.5, 'status_period_s': 0.3})
    status = graph.collect(DiagnosticStatus, 'rig_calibration/status', qos=10)
    assert graph.call(Trigger, 'rig_calibration/start', timeout=20.0).success
    imu_pub, image_pubs = _publishers(graph, truth)
    _feed(truth, poses, imu_pub, image_pubs, speed=2.0)
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline:
        messages = status.snapshot()[0]
        latest = {kv.key: kv.value for kv in messages[-1].values} if messages else {}
        if int(latest.get('captures', 0) or 0) >= len(poses):
            break
        time.sleep(0.2)
    finish = graph.call(Trigger, 'rig_calibration/finish', timeout=240.0)
    assert finish.success, finish.message + proc.output()
    tf_static = graph.collect(TFMessage, '/tf_static', qos=STATIC_TF_QOS)
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline and not tf_static.snapshot()[0]:
        time.sleep(0.05)
    (msg,) = tf_static.snapshot()[0]
    transforms = [msg_to_transform(m) for m in msg.transforms]
    assert check_tree(transforms) == 'imu_link'
    rig = load_rig(output)
    v = np.array([0.3, -1.2, 2.0])
    for cam in rig.cameras:
        r, t = to_ancestor(transforms, f'{cam.name}_optical_frame', 'imu_link')
        expected = rig.imu_to_camera.T @ (cam.R.T @ (v - cam.t))
        assert np.abs(r @ v + t - expected).max() < 1e-9, cam.name
    for name in truth.names:
        assert os.path.exists(str(output)[:-5] + f'_{name}_camera_info.yaml')
