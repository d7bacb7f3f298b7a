"""Graph test: the stitcher takes K and D from camera_info topics, checked against the sizes."""
import time

from accelcal_ros.camera.rig import ring_rig, save_rig
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA
import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo

TOPICS = ['cam0/camera_info', 'cam1/camera_info']


def _info(width, height, focal_px):
    msg = CameraInfo(width=width, height=height, distortion_model='plumb_bob')
    msg.k = [focal_px, 0.0, (width - 1) / 2.0, 0.0, focal_px, (height - 1) / 2.0, 0.0, 0.0, 1.0]
    msg.d = [0.01, 0.0, 0.0, 0.0, 0.0]
    return msg


def _start(graph, tmp_path, name):
    save_rig(tmp_path / 'rig.yaml', ring_rig(2, 64, 48, 55.0, 45.0,
                                             imu_to_camera=DEFAULT_IMU_TO_CAMERA))
    return graph.start('stitcher', name=name, params={
        'rig_file': str(tmp_path / 'rig.yaml'), 'camera_info_topics': TOPICS,
        'camera_info_timeout_s': 30.0})


def _feed_until(graph, proc, infos, text, timeout=40.0):
    pubs = [graph.node.create_publisher(CameraInfo, t, QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE)) for t in TOPICS]
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and text not in proc.output() \
            and proc.proc.poll() is None:
        for pub, info in zip(pubs, infos):
            pub.publish(info)
        time.sleep(0.1)
    return proc.output()


@pytest.mark.graph
def test_stitcher_uses_the_drivers_intrinsics(graph, tmp_path):
    """camera_info says f = 80 px (the rig file 55): the panorama is sized from 80."""
    proc = _start(graph, tmp_path, 'stitcher_info')
    out = _feed_until(graph, proc, [_info(64, 48, 80.0), _info(64, 48, 81.0)], 'stitching')
    assert 'camera 0 f = 80.0 px' in out, out
    assert proc.stop() == 0


@pytest.mark.graph
def test_stitcher_refuses_camera_info_of_another_size(graph, tmp_path):
    """A camera_info of 320x240 for 64x48 images: exit 1 with the topic and both sizes."""
    proc = _start(graph, tmp_path, 'stitcher_bad_info')
    out = _feed_until(graph, proc, [_info(64, 48, 80.0), _info(320, 240, 80.0)], 'stitching')
    assert proc.wait_exit(timeout=30.0) == 1, out
    out = proc.output()
    assert '/cam1/camera_info: camera_info is 320x240' in out and '64x48' in out, out
    assert 'Traceback' not in out
