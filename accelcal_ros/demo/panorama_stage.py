"""
Demo stage ``panorama``: a simulated 5-camera rig, the ``stitcher`` node, a levelled panorama.

Renders the rig's views of a synthetic scene for a swaying attitude (the rig's images are
written to ``<out>/panorama/``), starts the installed ``stitcher`` executable as its own
process, feeds it camera images and ``attitude`` from the probe as cameras and the
attitude node would, and prints what it publishes: rate, latency, lookup rebuilds, the
horizon check on every panorama, and what happens when a camera stalls. The last
panorama is written as PNG.
"""
import math
import os
import time

from accelcal_ros.camera.rig import ring_rig, save_rig
from accelcal_ros.fileio import write_bytes_atomic
from accelcal_ros.panorama import render
from accelcal_ros.panorama.projection import PanoramaGeometry
from accelcal_ros.rosutil.images import array_to_image_msg, image_msg_to_array
from accelcal_ros.rosutil.stamps import seconds_to_stamp, stamp_to_seconds
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3Stamped
import numpy as np
from sensor_msgs.msg import Image

RATE_HZ = 5.0


def _png(path, image):
    import cv2

    ok, data = cv2.imencode('.png', image)
    write_bytes_atomic(path, data.tobytes())


def _poses(count):
    """Swaying attitudes around the paper's reference pitch (15 deg nose down)."""
    k = np.arange(count)
    return [(math.radians(3.0 * math.sin(1.3 * i)), math.radians(15.0 + 2.0 * math.cos(0.9 * i)))
            for i in k]


def _diag(array_msgs, name):
    for array in reversed(array_msgs):
        for status in array.status:
            if status.name == name:
                return status
    return None


def run(ctx):
    """Run the stage (see the module docstring)."""
    out = os.path.join(ctx.out_dir, 'panorama')
    os.makedirs(out, exist_ok=True)
    rig = ring_rig(5, 640, 480, 550.0, 36.0, distortion=(-0.05, 0.01, 0.0, 0.0, 0.0),
                   mount_error_deg=0.3, seed=4)
    geometry = PanoramaGeometry(1800, 1200, 180.0, 120.0)
    rig_file = os.path.join(out, 'rig.yaml')
    save_rig(rig_file, rig)
    ctx.say(f'rig: 5 cameras 640x480, 60 deg FOV, 36 deg apart ({rig_file}); panorama '
            f'{geometry.width}x{geometry.height}, 180 x 120 deg spherical')
    start = time.monotonic()
    scene = render.make_scene(1800 if ctx.quick else 3600, 900 if ctx.quick else 1800)
    poses = _poses(3 if ctx.quick else 6)
    views = [render.render_camera_views(scene, rig, roll, pitch) for roll, pitch in poses]
    for i, image in enumerate(views[0]):
        _png(os.path.join(out, f'cam{i}.png'), image)
    truth = render.render_panorama_truth(scene, geometry)
    ctx.say(f'rendered {len(poses)} swaying attitudes x 5 views in '
            f'{time.monotonic() - start:.1f} s; camera images of the first written to '
            f'{out}/cam0..4.png')

    topics = [f'cam{i}/image_raw' for i in range(5)]
    proc = ctx.graph.start('stitcher', params={
        'rig_file': rig_file, 'width': geometry.width, 'height': geometry.height,
        'camera_topics': topics, 'stale_timeout_s': 0.8, 'image_reliability': 'reliable',
        # this demo sends one attitude per frame set (5 Hz) with large swings between sets,
        # not a 100 Hz IMU stream: only the attitude of the frames' own instant is right,
        # so match it tightly and allow it time to arrive on a loaded machine
        'attitude_tolerance_s': 0.01, 'attitude_wait_s': 0.2})
    node = ctx.graph.node
    pubs = [node.create_publisher(Image, t, 5) for t in topics]
    att_pub = node.create_publisher(Vector3Stamped, 'attitude', 10)
    panoramas = ctx.graph.collect(Image, 'panorama', 10)
    diagnostics = ctx.graph.collect(DiagnosticArray, '/diagnostics', 10)
    messages = [[array_to_image_msg(v, 'bgr8', Image) for v in pose_views]
                for pose_views in views]
    sent = {}

    def publish(k, cameras=range(5), attitude=True):
        pose = (k // int(RATE_HZ)) % len(poses)  # hold each attitude for a second
        now = time.time()
        stamp = seconds_to_stamp(now, Time)
        if attitude:
            att = Vector3Stamped()
            att.header.stamp = stamp
            att.vector.x, att.vector.y = poses[pose]
            att_pub.publish(att)
        for i in cameras:
            msg = messages[pose][i]
            msg.header.stamp = stamp
            pubs[i].publish(msg)
        sent[round(now, 6)] = pose

    deadline = time.monotonic() + 20.0
    while 'stitching 5 cameras' not in proc.output() and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(0.5)
    k = 0
    for k in range(15):  # frames without attitude: the node waits and says why once
        publish(k, attitude=False)
        time.sleep(1.0 / RATE_HZ)
        if 'no attitude received yet' in proc.output():
            break
    ctx.say('frames without attitude -> node: '
            + ('"no attitude received yet ... publishing nothing"'
               if 'no attitude received yet' in proc.output() else '(waiting)'))
    seconds = 5 if ctx.quick else 10
    horizon_errors, psnrs = [], []
    last = None
    next_report = time.monotonic() + 1.0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        k += 1
        publish(k)
        time.sleep(1.0 / RATE_HZ)
        if time.monotonic() >= next_report:
            next_report += 1.0
            msgs, times = panoramas.snapshot()
            recent = [(m, t) for m, t in zip(msgs, times) if t > time.time() - 1.0]
            lat = [t - stamp_to_seconds(m.header.stamp) for m, t in recent]
            status = _diag(diagnostics.snapshot()[0], 'stitcher: panorama')
            values = {kv.key: kv.value for kv in status.values} if status else {}
            if msgs:
                last = msgs[-1]
                pano = image_msg_to_array(last)
                rows = render.horizon_rows(pano, geometry)
                stamp = round(stamp_to_seconds(last.header.stamp), 6)
                horizon_errors.append(float(np.nanmax(np.abs(rows - geometry.horizon_row()))))
                pose = poses[sent.get(stamp, 0)]
                ctx.say(f'  t={seconds - (end - time.monotonic()):4.1f} s  panoramas '
                        f'{len(msgs):3d}  {len(recent):2d}/s  latency '
                        f'{1e3 * np.median(lat) if lat else float("nan"):5.0f} ms  attitude '
                        f'roll {math.degrees(pose[0]):+5.2f} pitch {math.degrees(pose[1]):5.2f}'
                        f' deg  node: {values.get("processing_ms", "?")} ms/frame, rebuilds '
                        f'{values.get("lookup_rebuilds", "?")} (last '
                        f'{values.get("last_rebuild_ms", "?")} ms)  horizon off by '
                        f'{horizon_errors[-1]:.2f} px')
    if last is None:
        raise RuntimeError('the stitcher published no panorama; see ' + proc.log_path)
    # keep the best-covered panorama of the run: a camera whose frames were all lost for
    # stale_timeout_s (large best-effort images on a loaded machine) counts as stalled
    coverages = [(image_msg_to_array(m).max(axis=2) > 0).mean()
                 for m in panoramas.snapshot()[0]]
    best = panoramas.snapshot()[0][int(np.argmax(coverages))]
    pano = image_msg_to_array(best)
    covered = pano.max(axis=2) > 0
    psnrs.append(render.psnr(pano, truth, covered))
    _png(os.path.join(out, 'panorama.png'), pano)
    full = sum(c >= max(coverages) - 0.005 for c in coverages)
    ctx.say(f'best panorama: {out}/panorama.png; PSNR against the scene '
            f'{psnrs[-1]:.1f} dB over the {100 * covered.mean():.0f} % covered '
            f'({full} of {len(coverages)} panoramas as complete); horizon within '
            f'{max(horizon_errors):.2f} px of row {geometry.horizon_row()} in every panorama '
            f'checked')
    # a camera stalls: its sector goes black, diagnostics report it, the others go on
    panoramas.clear()
    stall_end = time.monotonic() + 2.0
    while time.monotonic() < stall_end:
        k += 1
        publish(k, cameras=range(4))
        time.sleep(1.0 / RATE_HZ)
    status = _diag(diagnostics.snapshot()[0], 'stitcher: camera cam4')
    received = []
    for i in range(5):
        cam = _diag(diagnostics.snapshot()[0], f'stitcher: camera cam{i}')
        values = {kv.key: kv.value for kv in cam.values} if cam else {}
        received.append(values.get('received_frames', '?'))
    ctx.say(f'frame sets sent {len(sent)}; frames received by the node per camera: '
            f'{", ".join(received)}')
    msgs = panoramas.snapshot()[0]
    if msgs:
        stalled = image_msg_to_array(msgs[-1])
        _png(os.path.join(out, 'panorama_cam4_stalled.png'), stalled)
    ctx.say(f'cam4 stopped: {len(msgs)} panoramas in 2 s from the other four; diagnostics: '
            f'"{status.message if status else "?"}"; written panorama_cam4_stalled.png')
