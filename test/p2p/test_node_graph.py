"""The installed ``p2p`` node in a real ROS 2 graph: poses from rendered images, bad input."""
import time

from accelcal_ros.camera import CameraModel
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rpy_radians_from_rotation
from accelcal_ros.p2p import render, solver
import numpy as np
import pytest

EMITTERS = [-0.4, 0.0, 0.0, 0.4, 0.0, 0.0]
STATUS = 'p2p: P2P positioning'
"""The node's own status (its DropCounter publishes 'p2p: dropped messages' beside it)."""
CAMERA = CameraModel.from_fov(640, 480, 60.0)


def scene(yaw_deg):
    rotation, translation = render.pose_from_camera_attitude(
        np.radians(4.0), np.radians(20.0), np.radians(yaw_deg),
        [-3.0 * np.cos(np.radians(yaw_deg)), -3.0 * np.sin(np.radians(yaw_deg)), 1.1])
    image, _, _ = render.render_emitters(np.reshape(EMITTERS, (2, 3)), rotation, translation,
                                         CAMERA, noise_std=1.5)
    roll, pitch, _ = rpy_radians_from_rotation(rotation.T @ DEFAULT_IMU_TO_CAMERA)
    return image, rotation, translation, roll, pitch


class Probe:
    """Publishers of image, camera_info and attitude on the probe node."""

    def __init__(self, graph):
        from geometry_msgs.msg import Vector3Stamped
        from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import CameraInfo, Image

        node = graph.node
        self.node = node
        self.image = node.create_publisher(
            Image, 'image', QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE))
        self.info = node.create_publisher(CameraInfo, 'camera_info', 10)
        self.attitude = node.create_publisher(Vector3Stamped, 'attitude',
                                              qos_profile_sensor_data)

    def send(self, image, roll, pitch, info=True, encoding='mono8'):
        from accelcal_ros.rosutil.images import array_to_image_msg
        from geometry_msgs.msg import Vector3Stamped
        from sensor_msgs.msg import CameraInfo, Image

        stamp = self.node.get_clock().now().to_msg()
        att = Vector3Stamped()
        att.header.stamp = stamp
        att.vector.x, att.vector.y = float(roll), float(pitch)
        self.attitude.publish(att)
        if info:
            msg = CameraInfo()
            msg.header.stamp, msg.header.frame_id = stamp, 'cam_optical'
            msg.width, msg.height = CAMERA.width, CAMERA.height
            msg.k = [float(v) for v in CAMERA.camera_matrix.reshape(-1)]
            msg.d = [0.0] * 5
            msg.distortion_model = 'plumb_bob'
            self.info.publish(msg)
        msg = array_to_image_msg(image, 'mono8', Image)
        msg.header.stamp, msg.header.frame_id = stamp, 'cam_optical'
        if encoding != 'mono8':
            msg.encoding = encoding
        self.image.publish(msg)
        return stamp


def wait_for_reason(diag, fragment, probe, args, timeout=15.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        probe.send(*args[0], **args[1])
        time.sleep(0.2)
        messages, _ = diag.snapshot()
        for msg in messages:
            for status in msg.status:
                if status.name == STATUS and fragment in status.message:
                    return status
    seen = {s.message for m in diag.snapshot()[0] for s in m.status if s.name == STATUS}
    raise AssertionError(f'no diagnostics containing {fragment!r}; saw {seen}')


@pytest.mark.graph
def test_p2p_node_publishes_poses_from_rendered_images(graph):
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseStamped
    from geometry_msgs.msg import Vector3Stamped

    proc = graph.start('p2p', params={'emitters': EMITTERS, 'threshold': 60})
    poses = graph.collect(PoseStamped, 'pose', 10)
    yaws = graph.collect(Vector3Stamped, 'yaw', 10)
    diag = graph.collect(DiagnosticArray, '/diagnostics', 10)
    probe = Probe(graph)
    image, rotation, translation, roll, pitch = scene(150.0)
    deadline = time.monotonic() + 20.0
    while not poses.snapshot()[0] and time.monotonic() < deadline:
        assert proc.proc.poll() is None, proc.output()
        probe.send(image, roll, pitch)
        time.sleep(0.15)
    msgs = poses.wait_for(1, timeout=30.0)
    msg = msgs[-1]
    assert msg.header.frame_id == 'cam_optical'
    position = np.array([msg.pose.position.x, msg.pose.position.y, msg.pose.position.z])
    assert np.linalg.norm(position - translation) < 0.01 * np.linalg.norm(translation)
    q = msg.pose.orientation
    from scipy.spatial.transform import Rotation

    got = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    assert np.abs(got - rotation).max() < 2e-3
    yaw_msg = yaws.wait_for(1, timeout=30.0)[-1]
    assert yaw_msg.header.frame_id == 'cam_optical'   # stamped like the pose
    assert (yaw_msg.vector.x, yaw_msg.vector.y) == (0.0, 0.0)
    yaw = yaw_msg.vector.z
    assert abs(yaw - solver.yaw_from_rotation(rotation)) < 2e-3
    assert yaw == pytest.approx(np.radians(150.0), abs=2e-3)
    deadline = time.monotonic() + 30.0
    while not [s for m in diag.snapshot()[0] for s in m.status if s.name == STATUS] \
            and time.monotonic() < deadline:
        time.sleep(0.1)
    assert [s for m in diag.snapshot()[0] for s in m.status if s.name == STATUS]

    # Bad input keeps the node alive with a reason: wrong encoding, attitudes that are not
    # one (NaN, pitch 4 rad, roll 1e300: no pose from them), no blobs.
    wait_for_reason(diag, 'unsupported image encoding', probe,
                    ((image, roll, pitch), {'encoding': '16UC1'}))
    for bad in ((float('nan'), pitch), (roll, 4.0), (1e300, pitch)):  # refused, counted
        diag.clear()
        wait_for_reason(diag, 'attitude rejected', probe, ((image, *bad), {}))
    counts = [int(kv.value) for m in diag.snapshot()[0] for s in m.status
              for kv in s.values if kv.key == 'attitudes_rejected']
    assert max(counts) >= 3
    assert 'is not finite (attitudes dropped so far: 1;' in proc.output()  # throttled
    wait_for_reason(diag, 'no pixel above threshold', probe,
                    ((np.zeros_like(image), roll, pitch), {}))
    assert proc.proc.poll() is None


@pytest.mark.graph
def test_p2p_node_without_camera_info_reports_it(graph):
    from diagnostic_msgs.msg import DiagnosticArray

    proc = graph.start('p2p', params={'emitters': EMITTERS, 'threshold': 60})
    diag = graph.collect(DiagnosticArray, '/diagnostics', 10)
    probe = Probe(graph)
    image, _, _, roll, pitch = scene(0.0)
    status = wait_for_reason(diag, 'no camera_info', probe, ((image, roll, pitch),
                                                             {'info': False}))
    assert status.level == b'\x01' or status.level == 1
    result = graph.set_parameters('p2p', {'emitters': [0.0, 0.0, 0.0, 0.0, 0.0, 1.0]})
    assert not result[0].successful and 'vertical line' in result[0].reason
    assert proc.proc.poll() is None
