"""The ``stitcher`` with ``image_transport:=compressed`` in a real ROS 2 graph (issue 25)."""
import math
import time

from accelcal_ros.camera.rig import ring_rig, save_rig
from accelcal_ros.panorama import render
from accelcal_ros.panorama.projection import PanoramaGeometry
from accelcal_ros.rosutil.compressed import encode_compressed
from accelcal_ros.rosutil.images import image_msg_to_array
from accelcal_ros.rosutil.stamps import seconds_to_stamp, stamp_to_seconds
from builtin_interfaces.msg import Time
import cv2
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3Stamped
import numpy as np
import pytest
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CompressedImage, Image

ROLL, PITCH = math.radians(2.0), math.radians(10.0)
CAMERA_QOS = QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE)
TOPICS = ['cam0/image_raw', 'cam1/image_raw', 'cam2/image_raw']


class CompressedFeeder:
    """Publish the rig's views as image_transport's compressed plugin does, plus attitude."""

    def __init__(self, graph, views):
        node = graph.node
        self.pubs = [node.create_publisher(CompressedImage, f'{t}/compressed', CAMERA_QOS)
                     for t in TOPICS]
        self.att = node.create_publisher(Vector3Stamped, 'attitude', qos_profile_sensor_data)
        # cam0 JPEG bgr8, cam1 JPEG from rgb8, cam2 PNG from rgb8: every format honoured
        self.good = [encode_compressed(views[0], 'bgr8', 'jpeg', quality=95),
                     encode_compressed(np.ascontiguousarray(views[1][:, :, ::-1]), 'rgb8',
                                       'jpeg', quality=95),
                     encode_compressed(np.ascontiguousarray(views[2][:, :, ::-1]), 'rgb8',
                                       'png')]
        self.stamps = []

    def send(self, cam1=None):
        """One set at the current time; ``cam1``: ``(format, data)`` replacing cam1's frame."""
        now = time.time()
        att = Vector3Stamped()
        att.header.stamp = seconds_to_stamp(now, Time)
        att.vector.x, att.vector.y = ROLL, PITCH
        self.att.publish(att)
        for i, pub in enumerate(self.pubs):
            fmt, data = cam1 if (i == 1 and cam1 is not None) else self.good[i]
            msg = CompressedImage(format=fmt, data=data)
            msg.header.stamp = seconds_to_stamp(now, Time)
            msg.header.frame_id = f'cam{i}_optical'
            pub.publish(msg)
        self.stamps.append(now)
        return now


def _camera_status(diagnostics, name):
    messages = diagnostics.snapshot()[0]
    for array in reversed(messages):
        for status in array.status:
            if status.name == name:
                return {kv.key: kv.value for kv in status.values}, status
    return None, None


@pytest.mark.graph
def test_stitcher_compressed_input_and_bad_frames(graph, tmp_path):
    """JPEG/PNG frames make the panorama; corrupt ones are counted and skipped, once said."""
    rig = ring_rig(3, 320, 240, 275.0, 45.0)
    save_rig(tmp_path / 'rig.yaml', rig)
    geometry = PanoramaGeometry(720, 480)
    scene = render.make_scene(1800, 900, seed=2)
    views = render.render_camera_views(scene, rig, ROLL, PITCH)
    proc = graph.start('stitcher', params={
        'rig_file': str(tmp_path / 'rig.yaml'), 'width': 720, 'height': 480,
        'camera_topics': TOPICS, 'image_transport': 'compressed', 'stale_timeout_s': 2.0})
    panoramas = graph.collect(Image, 'panorama', 10)
    diagnostics = graph.collect(DiagnosticArray, '/diagnostics', 10)
    feeder = CompressedFeeder(graph, views)
    deadline = time.monotonic() + 30.0
    while len(panoramas.snapshot()[0]) < 3 and time.monotonic() < deadline:
        assert proc.proc.poll() is None, proc.output()
        feeder.send()
        time.sleep(0.1)
    msgs = panoramas.wait_for(3, timeout=30.0)
    assert 'compressed' in proc.output() and '/cam1/image_raw/compressed' in proc.output()
    panorama = image_msg_to_array(msgs[-1])
    truth = render.render_panorama_truth(scene, geometry)
    covered = panorama.max(axis=2) > 0
    # all three sectors present (cam1's and cam2's RGB data back in BGR order) and sharp
    assert covered[:, 100:620].mean() > 0.3
    assert render.psnr(panorama, truth, covered) > 26.0
    for sector in (slice(80, 200), slice(300, 420), slice(520, 640)):
        mask = covered.copy()
        mask[:, :sector.start] = False
        mask[:, sector.stop:] = False
        assert mask.sum() > 1000 and render.psnr(panorama, truth, mask) > 24.0

    # bad frames on cam1, every other set: each kind counted, said once, skipped
    fmt, jpeg = feeder.good[0]
    wrong_size = encode_compressed(cv2.resize(views[1], (160, 120)), 'bgr8', 'png')
    bad = [(fmt, jpeg[:len(jpeg) // 2]),                    # truncated JPEG
           (fmt, jpeg[:600] + bytes(2000) + jpeg[2600:]),   # corrupt JPEG
           wrong_size,                                      # PNG of the wrong size
           ('h264', jpeg)]                                  # not an image format
    panoramas.clear()
    bad_stamps = []
    sent_bad = 0
    start = time.monotonic()
    deadline = start + 40.0
    while time.monotonic() < deadline:
        feeder.send()
        time.sleep(0.1)
        bad_stamps.append(feeder.send(cam1=bad[sent_bad % len(bad)]))
        sent_bad += 1
        time.sleep(0.1)
        values, _ = _camera_status(diagnostics, 'stitcher: camera cam1')
        if sent_bad >= 8 and values and int(values['rejected_frames']) >= 8 and \
                len(panoramas.snapshot()[0]) >= 6:
            break
    assert proc.proc.poll() is None, proc.output()
    values, status = _camera_status(diagnostics, 'stitcher: camera cam1')
    assert 8 <= int(values['rejected_frames']) <= sent_bad, values
    assert values['topic'] == '/cam1/image_raw/compressed'
    got = panoramas.snapshot()[0]
    assert len(got) >= 6
    stamps = [stamp_to_seconds(m.header.stamp) for m in got]
    assert not any(min(abs(s - b) for b in bad_stamps) < 1e-6 for s in stamps)
    out = proc.output()
    elapsed = time.monotonic() - start   # each cause logged once per 10 s (throttled)
    for fragment in ('JPEG cut short', 'JPEG data does not decode',
                     'PNG image is 160x120, expected 320x240', "format 'h264'"):
        assert 1 <= out.count(fragment) <= 1 + int(elapsed // 10.0), (fragment, out)
    _, main = _camera_status(diagnostics, 'stitcher: panorama')
    keys = {kv.key: kv.value for kv in main.values}
    assert float(keys['decode_ms']) > 0.0 and 'decode_dropped' in keys
