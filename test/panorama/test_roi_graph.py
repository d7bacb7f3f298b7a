"""The stitcher's levelled views in a real ROS 2 graph: topics, K, steering, add/remove."""
import math
import time

from accelcal_ros.camera.rig import ring_rig, save_rig
from accelcal_ros.panorama import render
from accelcal_ros.panorama.roi_study import render_view_truth
from accelcal_ros.panorama.view import ViewPose
from accelcal_ros.rosutil.images import array_to_image_msg, image_msg_to_array
from accelcal_ros.rosutil.stamps import seconds_to_stamp
from builtin_interfaces.msg import Time
import cv2
from geometry_msgs.msg import Vector3Stamped
import numpy as np
import pytest
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image

ROLL, PITCH = math.radians(3.0), math.radians(7.0)
QOS = QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE)
TOPICS = ['cam0/image_raw', 'cam1/image_raw', 'cam2/image_raw']


def _feed_until(collector, count, feed, timeout=20.0, accept=lambda msg: True):
    """Call ``feed()`` every 0.1 s until ``collector`` holds ``count`` accepted messages."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        got = [m for m in collector.snapshot()[0] if accept(m)]
        if len(got) >= count:
            return got
        feed()
        time.sleep(0.1)
    return [m for m in collector.snapshot()[0] if accept(m)]


def _psnr_to_truth(msg, scene, pose):
    image = image_msg_to_array(msg)
    truth = render_view_truth(scene, msg.width, msg.height, pose)
    covered = cv2.erode((image.max(axis=2) > 0).astype(np.uint8), np.ones((5, 5), np.uint8))
    return covered.mean(), render.psnr(image, truth, covered.astype(bool))


@pytest.mark.graph
def test_views_published_steered_added_and_removed(graph, tmp_path):
    """roi/<name>/image matches the scene's view, camera_info holds K; steer/add/remove work.

    frame_id, set at run time, renames the views' frames; a bad one is refused.
    """
    rig = ring_rig(3, 320, 240, 275.0, 45.0, distortion=(-0.08, 0.01, 0, 0, 0))
    save_rig(tmp_path / 'rig.yaml', rig)
    scene = render.make_scene(1800, 900, seed=2)
    frames = render.render_camera_views(scene, rig, ROLL, PITCH)
    proc = graph.start('stitcher', params={
        'rig_file': str(tmp_path / 'rig.yaml'), 'width': 360, 'height': 240,
        'camera_topics': TOPICS, 'roi_views': ['front:10,2,50'], 'roi_width': 320,
        'roi_height': 240})
    node = graph.node
    pubs = [node.create_publisher(Image, t, QOS) for t in TOPICS]
    att = node.create_publisher(Vector3Stamped, 'attitude', qos_profile_sensor_data)
    steer = node.create_publisher(Vector3Stamped, 'roi/front/steer', 10)
    images = graph.collect(Image, 'roi/front/image', QOS)
    infos = graph.collect(CameraInfo, 'roi/front/camera_info', QOS)

    def feed():
        now = time.time()
        msg = Vector3Stamped()
        msg.header.stamp = seconds_to_stamp(now, Time)
        msg.vector.x, msg.vector.y = ROLL, PITCH
        att.publish(msg)
        for pub, image in zip(pubs, frames):
            header = Image().header
            header.stamp = seconds_to_stamp(now, Time)
            pub.publish(array_to_image_msg(image, 'bgr8', Image, header))

    got = _feed_until(images, 4, feed)
    assert len(got) >= 4, proc.output()
    msg = got[-1]
    assert (msg.width, msg.height, msg.encoding) == (320, 240, 'bgr8')
    assert msg.header.frame_id == 'panorama_roi_front'
    covered, psnr = _psnr_to_truth(msg, scene, ViewPose.from_degrees(10, 2, 50))
    assert covered > 0.5 and psnr > 30.0, (covered, psnr)

    def same_stamp(info):   # images go on arriving: pair an info with its own image
        stamps = {(m.header.stamp.sec, m.header.stamp.nanosec) for m in images.snapshot()[0]}
        return (info.header.stamp.sec, info.header.stamp.nanosec) in stamps

    info = _feed_until(infos, 1, feed, accept=same_stamp)[-1]
    f = 160 / math.tan(math.radians(25))
    assert np.allclose(info.k, [f, 0, 159.5, 0, f, 119.5, 0, 0, 1])
    assert (info.width, info.height) == (320, 240)
    assert info.header.frame_id == msg.header.frame_id

    # steering by the topic: x = azimuth, y = elevation, z = fov_h (rad)
    def steer_to(az, el, fov):
        m = Vector3Stamped()
        m.vector.x, m.vector.y, m.vector.z = math.radians(az), math.radians(el), \
            math.radians(fov)
        steer.publish(m)

    f30 = 160 / math.tan(math.radians(15))

    def steered(m):
        return abs(m.k[0] - f30) < 1e-6

    def feed_steer():
        steer_to(-30, 0, 30)
        feed()

    info = _feed_until(infos, 1, feed_steer, accept=steered)
    assert info, proc.output()
    images.clear()
    got = _feed_until(images, 4, feed)
    covered, psnr = _psnr_to_truth(got[-1], scene, ViewPose.from_degrees(-30, 0, 30))
    assert covered > 0.5 and psnr > 30.0, (covered, psnr)
    # a bad steer (fov 200 deg, NaN) is refused with the reason; the view keeps its pose
    steer_to(0, 0, 200)
    m = Vector3Stamped()
    m.vector.x = float('nan')
    steer.publish(m)
    deadline = time.monotonic() + 30
    while 'steer rejected' not in proc.output() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert 'fov_h must be in' in proc.output() or 'finite' in proc.output(), proc.output()
    infos.clear()
    assert steered(_feed_until(infos, 1, feed)[-1])

    # add two views and remove 'front' at run time; a bad name is refused, nothing applied
    bad = graph.set_parameters('stitcher', {'roi_views': ['front', 'no/slash']})
    assert not bad[0].successful and 'topic name' in bad[0].reason
    result = graph.set_parameters('stitcher', {'roi_views': ['side:40,0,60',
                                                             'left:-40,0,60']})
    assert result[0].successful, result[0].reason
    side = graph.collect(Image, 'roi/side/image', QOS)
    left = graph.collect(Image, 'roi/left/image', QOS)
    got = _feed_until(side, 4, feed)
    assert len(got) >= 4, proc.output()
    covered, psnr = _psnr_to_truth(got[-1], scene, ViewPose.from_degrees(40, 0, 60))
    assert covered > 0.3 and psnr > 30.0
    got = _feed_until(left, 4, feed)   # both drawn from each frame set, at once
    assert len(got) >= 4, proc.output()
    covered, psnr = _psnr_to_truth(got[-1], scene, ViewPose.from_degrees(-40, 0, 60))
    assert covered > 0.3 and psnr > 30.0
    images.clear()
    for _ in range(10):
        feed()
        time.sleep(0.1)
    assert images.snapshot()[0] == []  # 'front' is gone
    # too many views: refused with the cap
    result = graph.set_parameters('stitcher', {'roi_views': [f'v{i}' for i in range(9)]})
    assert not result[0].successful and 'at most 8' in result[0].reason
    # frame_id set at run time reaches the views; an empty or invalid one is refused
    for bad in ('', 'bad frame id', '/rig'):
        result = graph.set_parameters('stitcher', {'frame_id': bad})
        assert not result[0].successful and 'frame id' in result[0].reason, bad
    assert graph.set_parameters('stitcher', {'frame_id': 'rig_pano'})[0].successful
    side.clear()
    got = _feed_until(side, 2, feed, accept=lambda m: m.header.frame_id == 'rig_pano_roi_side')
    assert got, [m.header.frame_id for m in side.snapshot()[0]]


def _free_port():
    import socket

    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


@pytest.mark.graph
def test_live_views_in_a_browser_from_the_stitchers_frames(graph, tmp_path):
    """roi_serve_port: a WebSocket tab gets the live view of the stitcher's frame sets."""
    import asyncio
    import json

    aiohttp = pytest.importorskip('aiohttp')
    rig = ring_rig(3, 320, 240, 275.0, 45.0, distortion=(-0.08, 0.01, 0, 0, 0))
    save_rig(tmp_path / 'rig.yaml', rig)
    scene = render.make_scene(1800, 900, seed=2)
    frames = render.render_camera_views(scene, rig, ROLL, PITCH)
    port = _free_port()
    proc = graph.start('stitcher', params={
        'rig_file': str(tmp_path / 'rig.yaml'), 'width': 360, 'height': 240,
        'camera_topics': TOPICS, 'roi_width': 320, 'roi_height': 240,
        'roi_serve_port': port})
    node = graph.node
    pubs = [node.create_publisher(Image, t, QOS) for t in TOPICS]
    att = node.create_publisher(Vector3Stamped, 'attitude', qos_profile_sensor_data)

    def feed():
        now = time.time()
        msg = Vector3Stamped()
        msg.header.stamp = seconds_to_stamp(now, Time)
        msg.vector.x, msg.vector.y = ROLL, PITCH
        att.publish(msg)
        for pub, image in zip(pubs, frames):
            header = Image().header
            header.stamp = seconds_to_stamp(now, Time)
            pub.publish(array_to_image_msg(image, 'bgr8', Image, header))

    deadline = time.monotonic() + 60
    while 'live views in a browser' not in proc.output() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert f'127.0.0.1:{port}' in proc.output(), proc.output()

    async def tab():
        async with aiohttp.ClientSession() as session:
            ws = await session.ws_connect(f'http://127.0.0.1:{port}/ws')
            await ws.send_str(json.dumps({'az': 20, 'el': 1, 'fov': 50}))
            info, matching = None, 0
            loop = asyncio.get_running_loop()
            end = loop.time() + 60
            while loop.time() < end:
                feed()
                try:
                    msg = await ws.receive(timeout=0.2)
                except asyncio.TimeoutError:
                    continue
                if msg.type == aiohttp.WSMsgType.TEXT:
                    info = json.loads(msg.data)
                elif msg.type == aiohttp.WSMsgType.BINARY:
                    await ws.send_str(json.dumps({'ack': info['sent']}))
                    # the first sets may miss a camera (black sector): a few frames on
                    matching = matching + 1 if abs(info['az'] - 20) < 1e-6 else 0
                    if matching >= 5:
                        await ws.close()
                        return cv2.imdecode(np.frombuffer(msg.data, np.uint8),
                                            cv2.IMREAD_COLOR)
            return None

    image = asyncio.run(tab())
    assert image is not None, proc.output()
    truth = render_view_truth(scene, 320, 240, ViewPose.from_degrees(20, 1, 50))
    # what the cameras see, from the view's own lookup (JPEG rings at the black border)
    from accelcal_ros.panorama.view import LevelledView, ViewMosaic

    mosaic = ViewMosaic(rig)
    view = LevelledView(rig, mosaic.layout, 320, 240, ViewPose.from_degrees(20, 1, 50))
    view.set_attitude(ROLL, PITCH)
    white = np.zeros(mosaic.image.shape[:2], np.uint8)
    for (x0, y0), cam in zip(mosaic.layout.offsets, rig.cameras):
        white[y0:y0 + cam.height, x0:x0 + cam.width] = 255
    seen = cv2.remap(white, view.lookup(), None, cv2.INTER_LINEAR) == 255
    covered = cv2.erode(seen.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
    assert covered.mean() > 0.5 and render.psnr(image, truth, covered) > 28.0


@pytest.mark.graph
def test_browser_beyond_localhost_needs_a_token(graph, tmp_path):
    """roi_serve_host 0.0.0.0 without roi_serve_token: the node refuses to start, saying why."""
    rig = ring_rig(3, 320, 240, 275.0, 45.0)
    save_rig(tmp_path / 'rig.yaml', rig)
    proc = graph.start('stitcher', params={
        'rig_file': str(tmp_path / 'rig.yaml'), 'camera_topics': TOPICS,
        'roi_serve_port': _free_port(), 'roi_serve_host': '0.0.0.0'})
    assert proc.wait_exit(30.0) == 1, proc.output()
    assert 'roi_serve_token' in proc.output()
