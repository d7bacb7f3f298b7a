"""The ``p2p`` node with ``image_transport:=compressed`` in a real ROS 2 graph (issue 25)."""
import time

from accelcal_ros.camera import CameraModel
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rpy_radians_from_rotation
from accelcal_ros.p2p import render
from accelcal_ros.rosutil.compressed import encode_compressed
import numpy as np
import pytest

EMITTERS = [-0.4, 0.0, 0.0, 0.4, 0.0, 0.0]
CAMERA = CameraModel.from_fov(640, 480, 60.0)


def _scene(yaw_deg):
    rotation, translation = render.pose_from_camera_attitude(
        np.radians(4.0), np.radians(20.0), np.radians(yaw_deg),
        [-3.0 * np.cos(np.radians(yaw_deg)), -3.0 * np.sin(np.radians(yaw_deg)), 1.1])
    image, _, _ = render.render_emitters(np.reshape(EMITTERS, (2, 3)), rotation, translation,
                                         CAMERA, noise_std=1.5)
    roll, pitch, _ = rpy_radians_from_rotation(rotation.T @ DEFAULT_IMU_TO_CAMERA)
    return image, rotation, translation, roll, pitch


class CompressedProbe:
    """image/compressed (as image_transport publishes it), camera_info and attitude."""

    def __init__(self, graph):
        from geometry_msgs.msg import Vector3Stamped
        from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import CameraInfo, CompressedImage

        node = graph.node
        self.node = node
        self.image = node.create_publisher(
            CompressedImage, 'image/compressed',
            QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE))
        self.info = node.create_publisher(CameraInfo, 'camera_info', 10)
        self.attitude = node.create_publisher(Vector3Stamped, 'attitude',
                                              qos_profile_sensor_data)

    def send(self, fmt, data, roll, pitch):
        from geometry_msgs.msg import Vector3Stamped
        from sensor_msgs.msg import CameraInfo, CompressedImage

        stamp = self.node.get_clock().now().to_msg()
        att = Vector3Stamped()
        att.header.stamp = stamp
        att.vector.x, att.vector.y = float(roll), float(pitch)
        self.attitude.publish(att)
        info = CameraInfo(width=CAMERA.width, height=CAMERA.height,
                          k=[float(v) for v in CAMERA.camera_matrix.reshape(-1)],
                          d=[0.0] * 5, distortion_model='plumb_bob')
        info.header.stamp, info.header.frame_id = stamp, 'cam_optical'
        self.info.publish(info)
        msg = CompressedImage(format=fmt, data=data)
        msg.header.stamp, msg.header.frame_id = stamp, 'cam_optical'
        self.image.publish(msg)
        return stamp


def _p2p_values(diag):
    for msg in reversed(diag.snapshot()[0]):
        for status in msg.status:
            if status.name == 'p2p: P2P positioning':
                return {kv.key: kv.value for kv in status.values}, status
    return {}, None


@pytest.mark.graph
def test_p2p_compressed_input_poses_and_bad_frames(graph):
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseStamped

    proc = graph.start('p2p', params={'emitters': EMITTERS, 'threshold': 60,
                                      'image_transport': 'compressed'})
    poses = graph.collect(PoseStamped, 'pose', 10)
    diag = graph.collect(DiagnosticArray, '/diagnostics', 10)
    probe = CompressedProbe(graph)
    image, rotation, translation, roll, pitch = _scene(150.0)
    good = encode_compressed(image, 'mono8', 'png')
    deadline = time.monotonic() + 30.0
    while not poses.snapshot()[0] and time.monotonic() < deadline:
        assert proc.proc.poll() is None, proc.output()
        probe.send(*good, roll, pitch)
        time.sleep(0.15)
    msg = poses.wait_for(1, timeout=30.0)[-1]
    assert msg.header.frame_id == 'cam_optical'
    position = np.array([msg.pose.position.x, msg.pose.position.y, msg.pose.position.z])
    assert np.linalg.norm(position - translation) < 0.01 * np.linalg.norm(translation)
    # a JPEG of a colour camera (the plugin's "bgr8; jpeg compressed bgr8") works too
    colour = np.repeat(image[:, :, None], 3, axis=2)
    jpeg = encode_compressed(colour, 'bgr8', 'jpeg', quality=95)
    poses.clear()
    deadline = time.monotonic() + 20.0
    while not poses.snapshot()[0] and time.monotonic() < deadline:
        probe.send(*jpeg, roll, pitch)
        time.sleep(0.15)
    msg = poses.wait_for(1, timeout=30.0)[-1]
    position = np.array([msg.pose.position.x, msg.pose.position.y, msg.pose.position.z])
    assert np.linalg.norm(position - translation) < 0.01 * np.linalg.norm(translation)

    # bad frames: counted in /diagnostics, skipped, one (throttled) warning; node lives
    # a PNG of the wrong size decodes, and the pipeline refuses it against camera_info
    small = encode_compressed(image[::2, ::2].copy(), 'mono8', 'png')
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline:
        probe.send(*small, roll, pitch)
        time.sleep(0.15)
        _, status = _p2p_values(diag)
        if status is not None and 'does not match camera_info' in status.message:
            break
    assert 'image 320x240 does not match camera_info 640x480' in status.message
    fmt, data = jpeg
    bad = [(fmt, data[:len(data) // 3]), ('16UC1; compressedDepth png', data),
           (fmt, data[:20] + bytes(200) + data[220:])]
    sent = 0
    start = time.monotonic()
    deadline = start + 30.0
    while time.monotonic() < deadline:
        probe.send(*bad[sent % len(bad)], roll, pitch)
        sent += 1
        time.sleep(0.15)
        values, _ = _p2p_values(diag)
        if sent >= 6 and int(values.get('undecodable_frames', 0)) >= 6:
            break
    values, status = _p2p_values(diag)
    assert 6 <= int(values['undecodable_frames']) <= sent, values
    assert 'frame skipped' in status.message
    assert proc.proc.poll() is None, proc.output()
    # logged at most every 10 s (the DropCounter's throttle), whatever the load
    elapsed = time.monotonic() - start
    assert 1 <= proc.output().count('frame skipped:') <= 1 + int(elapsed // 10.0)
    poses.clear()
    deadline = time.monotonic() + 20.0
    while not poses.snapshot()[0] and time.monotonic() < deadline:
        probe.send(*good, roll, pitch)
        time.sleep(0.15)
    assert poses.wait_for(1, timeout=30.0)
