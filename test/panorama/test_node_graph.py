"""The ``stitcher`` executable in a real ROS 2 graph (e.g. 3 cameras 320x240 -> 720x480)."""
import math
import os
import re
import time

from accelcal_ros.camera.rig import ring_rig, save_rig
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA
from accelcal_ros.panorama import render
from accelcal_ros.panorama.params import panorama_size_from_focal
from accelcal_ros.panorama.projection import PanoramaGeometry
from accelcal_ros.rosutil.images import array_to_image_msg, image_msg_to_array
from accelcal_ros.rosutil.stamps import seconds_to_stamp, stamp_to_seconds
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3Stamped
import numpy as np
import pytest
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CompressedImage, Image

ROLL, PITCH = math.radians(2.0), math.radians(10.0)
CAMERA_QOS = QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE)
"""What camera drivers publish with (and what the node subscribes with by default)."""


class Feeder:
    """Publish rig images (and attitude) from the probe, like cameras and the IMU."""

    def __init__(self, graph, views, topics):
        self.node = graph.node
        self.views = views
        self.pubs = [self.node.create_publisher(Image, t, CAMERA_QOS) for t in topics]
        self.att = self.node.create_publisher(Vector3Stamped, 'attitude',
                                              qos_profile_sensor_data)
        self.stamps = []

    def frames(self, cameras=None, encoding='bgr8', offset_s=0.0):
        now = time.time() + offset_s
        self.stamps.append(now)
        for i, pub in enumerate(self.pubs):
            if cameras is not None and i not in cameras:
                continue
            image = self.views[i]
            if encoding != 'bgr8':               # one-channel data: 16UC1 (refused), Bayer
                image = image[:, :, 0].copy()
            header = Image().header
            header.stamp = seconds_to_stamp(now, Time)
            msg = array_to_image_msg(image, 'bgr8' if encoding == 'bgr8' else 'mono8', Image,
                                     header)
            msg.encoding = encoding
            pub.publish(msg)
        return now

    def attitude(self, roll, pitch, offset_s=0.0):
        msg = Vector3Stamped()
        msg.header.stamp = seconds_to_stamp(time.time() + offset_s, Time)
        msg.vector.x, msg.vector.y = roll, pitch
        self.att.publish(msg)


def _wait_for_log(proc, text, timeout=30.0, feed=None):
    """Wait for ``text`` in the node's output, calling ``feed()`` every 0.1 s meanwhile."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if text in proc.output():
            return True
        if feed is not None:
            feed()
        time.sleep(0.1)
    return False


def _feed_until(collector, count, feed, timeout=15.0):
    """Call ``feed()`` every 0.1 s until ``collector`` holds ``count`` messages."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and len(collector.snapshot()[0]) < count:
        feed()
        time.sleep(0.1)
    return collector.wait_for(count, timeout=1.0)


@pytest.mark.graph
def test_stitcher_node_end_to_end(graph, tmp_path):
    """No attitude: silence (said once); then panoramas; a stalled camera goes black."""
    rig = ring_rig(3, 320, 240, 275.0, 45.0, distortion=(-0.08, 0.01, 0, 0, 0))
    save_rig(tmp_path / 'rig.yaml', rig)
    geometry = PanoramaGeometry(720, 480)
    scene = render.make_scene(1800, 900, seed=2)
    views = render.render_camera_views(scene, rig, ROLL, PITCH)
    topics = ['cam0/image_raw', 'cam1/image_raw', 'cam2/image_raw']
    proc = graph.start('stitcher', params={
        'rig_file': str(tmp_path / 'rig.yaml'), 'width': 720, 'height': 480,
        'stale_timeout_s': 0.6, 'camera_topics': topics})
    panoramas = graph.collect(Image, 'panorama', 10)
    diagnostics = graph.collect(DiagnosticArray, '/diagnostics', 10)
    feeder = Feeder(graph, views, topics)
    assert _wait_for_log(proc, 'stitching 3 cameras', 15.0), proc.output()
    # a 1 MB panorama does not fit Fast DDS's default shared-memory segment: the node uses
    # config/fastdds_large_shm.xml and says so
    from rclpy.utilities import get_rmw_implementation_identifier
    if get_rmw_implementation_identifier() == 'rmw_fastrtps_cpp' and not any(
            os.environ.get(k) for k in ('FASTRTPS_DEFAULT_PROFILES_FILE',
                                        'FASTDDS_DEFAULT_PROFILES_FILE')):
        # the node takes the shipped profile itself and says what the drivers need
        assert 'panoramas of 1.0 MB exceed Fast DDS' in proc.output(), proc.output()
        assert 'fastdds_large_shm.xml' in proc.output(), proc.output()
    assert _wait_for_log(proc, 'no attitude received yet', 15.0, feeder.frames), proc.output()
    assert panoramas.snapshot()[0] == []

    def bad_inputs():
        feeder.attitude(float('nan'), 0.0)
        feeder.frames(cameras=[1], encoding='16UC1')

    assert _wait_for_log(proc, 'attitude rejected', 30.0, bad_inputs), proc.output()
    assert _wait_for_log(proc, "unsupported image encoding '16UC1'", 30.0, bad_inputs)

    def good():
        feeder.attitude(ROLL, PITCH)
        feeder.frames()

    msgs = _feed_until(panoramas, 3, good)
    assert proc.output().count('no attitude received yet') == 1
    last = msgs[-1]
    assert (last.width, last.height, last.encoding) == (720, 480, 'bgr8')
    assert min(abs(stamp_to_seconds(last.header.stamp) - s) for s in feeder.stamps) < 1e-6
    panorama = image_msg_to_array(last)
    truth = render.render_panorama_truth(scene, geometry)
    covered = panorama.max(axis=2) > 0
    assert covered.mean() > 0.2 and render.psnr(panorama, truth, covered) > 28.0
    rows = render.horizon_rows(panorama, geometry)
    assert np.nanmax(np.abs(rows - 239.5)) < 1.0
    # camera 2 stalls: the others go on, its sector turns black, diagnostics say so
    left_sector = covered.copy()
    left_sector[:, 300:] = False

    def two_cameras():
        feeder.attitude(ROLL, PITCH)
        feeder.frames(cameras=[0, 1])

    assert _wait_for_log(proc, 'cam2 (cam2/image_raw) stalled', 30.0, two_cameras)
    panoramas.clear()
    msgs = _feed_until(panoramas, 2, two_cameras)
    stalled = image_msg_to_array(msgs[-1])
    assert stalled[:, :150].max() == 0 and stalled[:, 330:390].max() > 0

    def stalled_status():
        for array in diagnostics.snapshot()[0]:
            for status in array.status:
                if status.name == 'stitcher: camera cam2' and 'stalled' in status.message:
                    return status
        return None

    deadline = time.monotonic() + 30.0
    while stalled_status() is None and time.monotonic() < deadline:
        time.sleep(0.1)
    assert stalled_status() is not None
    # camera 2 is back (an info line after the warnings: one logger, two severities)
    assert _wait_for_log(proc, 'cam2 (cam2/image_raw) is back', 30.0, good), proc.output()
    assert 'stitching failed' not in proc.output()
    assert proc.proc.poll() is None


@pytest.mark.graph
def test_stitcher_node_refuses_a_bad_rig(graph, tmp_path):
    """A rig file with a non-rotation R: one clear error line naming the camera, exit 1."""
    (tmp_path / 'rig.yaml').write_text(
        'cameras:\n- {name: front, width: 32, height: 24, K: [30,0,16,0,30,12,0,0,1],'
        ' R: [1,0,0,0,1,0,0,0,1]}\n- {name: side, width: 32, height: 24, '
        'K: [30,0,16,0,30,12,0,0,1], R: [1,0,0,0,1,0,0,0,3]}\n')
    proc = graph.start('stitcher', params={'rig_file': str(tmp_path / 'rig.yaml')})
    assert proc.wait_exit(timeout=20.0) == 1
    assert "camera 1 ('side'): R: not a rotation" in proc.output()


@pytest.mark.graph
def test_stitcher_node_reports_unsynchronised_and_wrong_size_frames(graph, tmp_path):
    """Cameras never within sync_tolerance_s are reported once; wrong sizes rejected."""
    rig = ring_rig(2, 64, 48, 55.0, 45.0, imu_to_camera=DEFAULT_IMU_TO_CAMERA)
    save_rig(tmp_path / 'rig.yaml', rig)
    proc = graph.start('stitcher', params={
        'rig_file': str(tmp_path / 'rig.yaml'), 'width': 180, 'height': 120,
        'sync_tolerance_s': 0.001, 'image_reliability': 'best_effort',
        'imu_to_camera': [0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0]})
    pubs = [graph.node.create_publisher(Image, f'cam{i}/image_raw', qos_profile_sensor_data)
            for i in range(2)]
    att = graph.node.create_publisher(Vector3Stamped, 'attitude', qos_profile_sensor_data)
    image = np.full((48, 64, 3), 128, np.uint8)
    wrong = np.zeros((10, 10, 3), np.uint8)

    def feed():
        now = time.time()
        msg = Vector3Stamped()
        msg.header.stamp = seconds_to_stamp(now, Time)
        att.publish(msg)
        for i, pub in enumerate(pubs):
            header = Image().header
            # cam1 0.5 s ahead: its newest frame is the newest whichever topic is
            # delivered first, while feed() runs every 0.1 s
            header.stamp = seconds_to_stamp(now + 0.5 * i, Time)
            pub.publish(array_to_image_msg(image, 'bgr8', Image, header))
        header = Image().header
        header.stamp = seconds_to_stamp(now, Time)
        pubs[1].publish(array_to_image_msg(wrong, 'bgr8', Image, header))

    assert _wait_for_log(proc, 'no set of frames with stamps within', 20.0, feed), \
        proc.output()
    # offsets from the newest frame (cam1's): -500 ms, give or take the feeds in flight
    offset = re.search(r'offsets from the newest frame: cam0 \(cam0/image_raw\) ([+-]\d+) ms',
                       proc.output())
    assert offset and -800 <= int(offset.group(1)) <= -250, proc.output()
    assert 'image on cam1/image_raw: bgr8 image is 10x10, expected 64x48' in proc.output()
    assert proc.output().count('no set of frames with stamps within') == 1
    assert 'imu_to_camera from parameter imu_to_camera' in proc.output()


@pytest.mark.graph
def test_stitcher_node_goes_on_after_time_jumps(graph, tmp_path):
    """A set stamped in the future, then the clock going back: panoramas resume, said."""
    rig = ring_rig(2, 64, 48, 55.0, 45.0, imu_to_camera=DEFAULT_IMU_TO_CAMERA)
    save_rig(tmp_path / 'rig.yaml', rig)
    topics = ['cam0/image_raw', 'cam1/image_raw']
    proc = graph.start('stitcher', params={        # the default listed: the rig's wins
        'rig_file': str(tmp_path / 'rig.yaml'),    # size: the rig's (f = 55 px)
        'camera_topics': topics, 'compressed_output': True,
        'imu_to_camera': [float(v) for v in DEFAULT_IMU_TO_CAMERA.reshape(-1)]})
    panoramas = graph.collect(Image, 'panorama', 10)
    compressed = graph.collect(CompressedImage, 'panorama/compressed', 10)
    diagnostics = graph.collect(DiagnosticArray, '/diagnostics', 10)
    views = [np.full((48, 64, 3), 60 + 100 * i, np.uint8) for i in range(2)]
    feeder = Feeder(graph, views, topics)
    # a best-effort camera driver is not received by the (reliable) default: said
    graph.node.create_publisher(Image, 'cam1/image_raw', qos_profile_sensor_data)
    offset = [0.0]

    def feed():
        feeder.attitude(0.0, 0.0, offset[0])
        feeder.frames(offset_s=offset[0])

    assert _feed_until(panoramas, 2, feed, 20.0), proc.output()
    # the default size: 55 px/rad over 180 x 120 deg, rounded to even (172.8 x 115.2)
    first = panoramas.snapshot()[0][0]
    assert (first.width, first.height) == panorama_size_from_focal(55.0, 180.0, 120.0) \
        == (172, 116)
    assert 'into a 172x116 spherical panorama' in proc.output()
    assert 'size from the rig: camera 0 f = 55.0 px' in proc.output()
    assert 'incompatible QoS' in proc.output()
    assert 'imu_to_camera from rig file' in proc.output()
    assert compressed.wait_for(1, timeout=30.0)
    jpeg = compressed.snapshot()[0][-1]
    assert jpeg.format == 'bgr8; jpeg compressed bgr8' and bytes(jpeg.data[:2]) == b'\xff\xd8'
    for jump_s in (1000.0, -1000.0):
        offset[0] = jump_s
        feed()                           # one set stamped 1000 s ahead, or a bag loop
        time.sleep(0.3)
        offset[0] = 0.0 if jump_s > 0 else -1000.0
        panoramas.clear()
        msgs = _feed_until(panoramas, 3, feed, 20.0)
        assert len(msgs) >= 3, proc.output()
        assert abs(stamp_to_seconds(msgs[-1].header.stamp) - time.time() - offset[0]) < 5.0
    assert 'time jump of' in proc.output()

    def jumps():
        for array in diagnostics.snapshot()[0]:
            for status in array.status:
                values = {kv.key: kv.value for kv in status.values}
                if status.name == 'stitcher: panorama' and int(values['time_jumps']) >= 2:
                    return values
        return None

    deadline = time.monotonic() + 30.0
    while jumps() is None and time.monotonic() < deadline:
        feed()
        time.sleep(0.1)
    assert jumps() is not None, proc.output()
    # the jump is the stamps' -1000 s plus the probe's wall time between the two messages
    # the node compared (up to the feed loop's timeout) minus the node's wall time between
    # receiving them: it differs from the probe's by the two messages' delivery delays
    # (a loaded machine: measured 15 ms, bounded here by the feed loop's timeout too)
    jump_s = float(jumps()['last_time_jump'].split(' s ')[0])
    assert -1000.0 - 20.0 <= jump_s <= -1000.0 + 20.0, jumps()['last_time_jump']
    assert jumps()['last_error'] == 'none' and 'stitching failed' not in proc.output()

    # raw cameras' encodings: Bayer frames (uniform grey 60 and 160) are demosaiced
    def bayer():
        feeder.attitude(0.0, 0.0, offset[0])
        feeder.frames(encoding='bayer_rggb8', offset_s=offset[0])

    panoramas.clear()
    msgs = _feed_until(panoramas, 2, bayer, 20.0)
    assert len(msgs) >= 2 and 'frame rejected' not in proc.output(), proc.output()
    values = image_msg_to_array(msgs[-1])
    values = values[values.max(axis=2) > 0]
    inside = (values >= 55) & (values <= 165)          # the rest: edges blended with black
    assert inside.mean() > 0.9 and values.max() <= 165
    assert (np.abs(values.astype(int) - 60) <= 2).any() and \
        (np.abs(values.astype(int) - 160) <= 2).any()
    assert proc.proc.poll() is None
