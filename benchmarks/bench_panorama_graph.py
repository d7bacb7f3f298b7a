"""
Benchmark of the ``stitcher`` node in a real ROS graph (issue 16): panoramas per second.

One run, one machine, processes as a user has them:

1. a **publisher process**: N cameras (bgr8, reliable, one stamp per set, as camera
   drivers publish) at a size and rate, and an attitude stream at 100 Hz (sensor-data
   QoS, the tilt moving so that the lookup is rebuilt for every set);
2. the **floor**: a bare rclpy subscriber process to the N topics (no processing; the
   node's default image QoS), counting complete frame sets per second -- deserialising
   (what the issue measured) and raw (serialized bytes, what the node takes);
3. the **node with defaults** (only ``rig_file`` and ``camera_topics`` set) and a
   subscriber process of ``panorama`` with the node's publisher QoS (reliable, depth 2),
   counting panoramas per second and the latency (frame stamp to panorama receipt);
4. the node again with nobody subscribing ``panorama`` (it then skips serialising and
   publishing): its own rate, from ``/diagnostics``. The difference is the cost of
   moving the panorama (26 MB at 3600x2400, 6 MB at 1728x1152) from process to process.

Targets (issue 16): the stitcher's rate at least 0.9x the floor's complete frame sets
(same run), and 25 fps for 5 x 640x480 at 25 Hz. ``--stages`` prints the per-set cost
of each stage in one process (take/deserialise, convert, copy into the mosaic, rebuild,
remap, build + publish), the node's path before (deserialised messages, arrays copied)
and now (raw buffers, numpy views, serialized output). Short runs are indicative only:
Run: ``python benchmarks/bench_panorama_graph.py [--duration 10] [--configs 5x1280x960@10
5x640x480@25] [--stages] [--size 3600x2400] [--shm-mb 128]`` (``--size``: a fixed
panorama size, as before issue 16; default: the node's, the cameras' resolution;
``--shm-mb``: see :data:`FASTDDS_LARGE_SHM`, without it the transport is the limit).

``--hosts 2`` (issue 25, :mod:`panorama_hosts`): the cameras on host A, the bare
subscriber and the stitcher on host B (network namespaces joined by a veth pair shaped to
``--link-rate``, 1 Gbit/s), raw ``sensor_msgs/Image`` against image_transport's
``compressed`` JPEG; complete sets/s at B, panoramas/s, the link's throughput and the
decode cost per set. Needs root and ``ip netns``.
"""
import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.abspath(__file__)
CONFIGS = ('5x1280x960@10', '5x640x480@25')


# -- child processes --------------------------------------------------------------------
def _init(name):
    import rclpy

    rclpy.init()
    return rclpy, rclpy.create_node(name)


def _spin_for(rclpy, node, seconds, stop=None):
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor()
    executor.add_node(node)
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and not (stop and stop()):
        executor.spin_once(timeout_sec=0.05)


def publisher(args):
    """Publish N camera streams at ``rate`` (one stamp per set) and attitude at 100 Hz."""
    import threading

    from accelcal_ros.rosutil.images import array_to_image_msg
    from geometry_msgs.msg import Vector3Stamped
    from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CameraInfo, CompressedImage, Image

    rclpy, node = _init('bench_cameras')
    qos = QoSProfile(depth=args.pub_depth, reliability=ReliabilityPolicy.RELIABLE)
    topics = args.topics.split(',')
    compressed = args.transport == 'compressed'
    pubs = [node.create_publisher(CompressedImage, f'{t}/compressed', qos) if compressed
            else node.create_publisher(Image, t, qos) for t in topics]
    att = node.create_publisher(Vector3Stamped, 'attitude', qos_profile_sensor_data)
    if args.image_npy:
        images = [np.load(args.image_npy)] * len(topics)
    elif args.rig:                          # the rig's views of a scene: real JPEG sizes
        from panorama_hosts import rendered_views

        images = rendered_views(args.rig, args.encoding)
    else:
        rng = np.random.default_rng(1)
        shape = (args.height, args.width) + ((3,) if args.encoding == 'bgr8' else ())
        images = [rng.integers(0, 256, shape, dtype=np.uint8) for _ in topics]
    if compressed:
        from accelcal_ros.rosutil.compressed import encode_compressed

        msgs = [CompressedImage(format=fmt, data=data) for fmt, data in (
            encode_compressed(img, args.encoding, 'jpeg', args.jpeg_quality) for img in images)]
    else:
        msgs = [array_to_image_msg(img, args.encoding, Image) for img in images]
    for msg in msgs:
        msg.header.frame_id = 'camera_optical'
    info_pub, info = None, None
    if args.camera_info:
        values = json.loads(args.camera_info)
        info_pub = node.create_publisher(CameraInfo, 'camera_info', 10)
        info = CameraInfo(width=values['width'], height=values['height'],
                          k=[float(v) for v in values['K']], d=[0.0] * 5,
                          distortion_model='plumb_bob')
        info.header.frame_id = 'camera_optical'
    stop = threading.Event()

    def attitude_loop():
        start = time.time()
        while not stop.is_set():
            now = time.time()
            msg = Vector3Stamped()
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(now * 1e9), 10 ** 9)
            t = now - start
            wobble = math.radians(args.wobble_deg)
            msg.vector.x = math.radians(args.roll_deg) + wobble * math.sin(0.5 * t)
            msg.vector.y = math.radians(args.pitch_deg) + wobble * math.sin(0.3 * t)
            att.publish(msg)
            stop.wait(0.01)

    thread = threading.Thread(target=attitude_loop, daemon=True)
    thread.start()
    period = 1.0 / args.rate
    next_t = time.monotonic() + 0.5
    deadline = time.monotonic() + args.duration
    while time.monotonic() < deadline:
        delay = next_t - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        next_t += period
        sec, nanosec = divmod(int(time.time() * 1e9), 10 ** 9)
        if info_pub is not None:
            info.header.stamp.sec, info.header.stamp.nanosec = sec, nanosec
            info_pub.publish(info)
        for pub, msg in zip(pubs, msgs):
            msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
            pub.publish(msg)
    stop.set()
    thread.join()
    rclpy.shutdown()


def bare(args):
    """Subscribe the N topics without processing; count complete frame sets."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rclpy.serialization import deserialize_message  # noqa: F401 - rclpy ready
    from sensor_msgs.msg import Image

    rclpy, node = _init('bench_bare')
    qos = QoSProfile(depth=args.sub_depth, reliability=ReliabilityPolicy.RELIABLE)
    topics = args.topics.split(',')
    seen, state = {}, {'complete': 0, 'first': None, 'frames': 0}

    def on_frame(stamp):
        now = time.monotonic()
        if state['first'] is None:
            state['first'] = now
        if now - state['first'] < args.warmup:
            return
        state['frames'] += 1
        seen[stamp] = seen.get(stamp, 0) + 1
        if seen[stamp] == len(topics):
            state['complete'] += 1
            del seen[stamp]

    for topic in topics:
        if args.transport == 'compressed':  # image_transport's topic, stamps read raw
            from accelcal_ros.rosutil.compressed import parse_compressed_cdr
            from sensor_msgs.msg import CompressedImage

            node.create_subscription(CompressedImage, f'{topic}/compressed', lambda d: on_frame(
                parse_compressed_cdr(d).stamp_s), qos, raw=True)
        elif args.raw:
            from accelcal_ros.rosutil.images import parse_image_cdr

            node.create_subscription(Image, topic, lambda d: on_frame(
                parse_image_cdr(d).stamp_s), qos, raw=True)
        else:
            node.create_subscription(Image, topic, lambda m: on_frame(
                (m.header.stamp.sec, m.header.stamp.nanosec)), qos)
    started = time.monotonic()
    _spin_for(rclpy, node, 60.0, lambda: state['first'] is not None)
    _spin_for(rclpy, node, args.warmup + args.duration)
    span = args.duration
    print(json.dumps({'sets_per_s': state['complete'] / span,
                      'frames_per_s': state['frames'] / span,
                      'waited_s': time.monotonic() - started - args.warmup - span}))
    rclpy.shutdown()


def sink(args):
    """Count messages of ``--topic`` (Image raw, or PoseStamped) and their latency."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    rclpy, node = _init('bench_sink')
    qos = QoSProfile(depth=args.sub_depth, reliability=ReliabilityPolicy.RELIABLE)
    state = {'first': None, 'count': 0, 'latency': [], 'diag': {}}

    def on_msg(stamp_s):
        now = time.monotonic()
        if state['first'] is None:
            state['first'] = now
        if now - state['first'] < args.warmup:
            return
        state['count'] += 1
        state['latency'].append(time.time() - stamp_s)

    if args.msg_type == 'image':
        from accelcal_ros.rosutil.images import parse_image_cdr
        from sensor_msgs.msg import Image

        node.create_subscription(Image, args.topic, lambda d: on_msg(
            parse_image_cdr(d).stamp_s), qos, raw=True)
    else:
        from geometry_msgs.msg import PoseStamped

        node.create_subscription(PoseStamped, args.topic, lambda m: on_msg(
            m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec), qos)

    received = []                           # (time, frames the node received, all cameras)

    def on_diag(msg):
        frames = 0
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if status.name.startswith(args.diag_prefix):
                state['diag'] = values
            frames += int(values.get('received_frames', 0))
        received.append((time.monotonic(), frames))

    def input_rate():
        """Frames per second the node received (all cameras, its diagnostics)."""
        start = time.monotonic() - args.duration
        window = [r for r in received if r[0] >= start]
        if len(window) < 2 or window[-1][0] <= window[0][0]:
            return math.nan
        return (window[-1][1] - window[0][1]) / (window[-1][0] - window[0][0])

    node.create_subscription(DiagnosticArray, '/diagnostics', on_diag, 10)
    if args.diag_only:                      # nobody subscribes the output: the node's rate
        _spin_for(rclpy, node, 90.0, lambda: state['diag'].get('published', '0') != '0')
        _spin_for(rclpy, node, args.warmup + args.duration)
        print(json.dumps({'per_s': float(state['diag'].get('rate_hz', 'nan')),
                          'node_input_frames_per_s': input_rate(),
                          'diagnostics': state['diag']}))
        rclpy.shutdown()
        return
    _spin_for(rclpy, node, 90.0, lambda: state['first'] is not None)
    _spin_for(rclpy, node, args.warmup + args.duration)
    lat = sorted(state['latency']) or [math.nan]
    print(json.dumps({'per_s': state['count'] / args.duration,
                      'latency_ms': 1e3 * statistics.median(lat),
                      'latency_p90_ms': 1e3 * lat[int(0.9 * (len(lat) - 1))],
                      'node_input_frames_per_s': input_rate(),
                      'diagnostics': state['diag']}))
    rclpy.shutdown()


# -- the parent -------------------------------------------------------------------------
def child(role, *options, prefix=()):
    """Start this script as ``role`` (a process; ``prefix``: e.g. ip netns exec); stdout kept."""
    return subprocess.Popen([*prefix, sys.executable, HERE, '--role', role,
                             *map(str, options)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def result_of(proc, timeout):
    """Return the JSON a child printed, or {'error': ...}."""
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
    for line in reversed(out.splitlines()):
        if line.startswith('{'):
            return json.loads(line)
    return {'error': (err or out).strip().splitlines()[-3:]}


FASTDDS_LARGE_SHM = """<?xml version="1.0" encoding="UTF-8"?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <transport_descriptors>
    <transport_descriptor>
      <transport_id>shm_large</transport_id>
      <type>SHM</type>
      <segment_size>{segment_bytes}</segment_size>
    </transport_descriptor>
    <transport_descriptor>
      <transport_id>udp</transport_id>
      <type>UDPv4</type>
    </transport_descriptor>
  </transport_descriptors>
  <participant profile_name="large_messages" is_default_profile="true">
    <rtps>
      <userTransports>
        <transport_id>shm_large</transport_id>
        <transport_id>udp</transport_id>
      </userTransports>
      <useBuiltinTransports>false</useBuiltinTransports>
    </rtps>
  </participant>
</profiles>
"""
"""
Fast DDS profile: a shared-memory segment large enough for camera frames and panoramas.

Fast DDS's default segment (0.5 MB) does not hold a 0.9 MB 640x480 frame: such messages
go over UDP loopback in 64 kB fragments, and at 100+ MB/s fragments are lost, so keep-last
readers lose whole frames (complete sets drop from 25 to 11-14/s even for a bare
subscriber). Every process of the graph must use it (``FASTRTPS_DEFAULT_PROFILES_FILE``).
"""


def use_fastdds_profile(segment_mb, workdir):
    """Write :data:`FASTDDS_LARGE_SHM` and point this process and its children to it."""
    path = os.path.join(workdir, 'fastdds_large_shm.xml')
    with open(path, 'w') as handle:
        handle.write(FASTDDS_LARGE_SHM.format(segment_bytes=int(segment_mb * 2 ** 20)))
    os.environ['FASTRTPS_DEFAULT_PROFILES_FILE'] = path
    os.environ['FASTDDS_DEFAULT_PROFILES_FILE'] = path
    return path


def isolated_domain():
    """Give this run its own ROS domain (localhost only); returns the holder."""
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    try:
        from graph_harness.domain import allocate_domain_id
    except ImportError:
        return None
    holder = allocate_domain_id()
    os.environ['ROS_DOMAIN_ID'] = str(holder.domain_id)
    return holder


def run_graph(publisher_options, phases, duration, warmup):
    """
    Run the publisher for every phase; ``phases``: ``[(label, start)]``.

    ``start()`` returns ``(processes to stop, the process whose JSON is the result)``.
    Returns ``{label: result}``.
    """
    total = len(phases) * (duration + warmup + 25.0) + 10.0
    pub = child('publisher', *publisher_options, '--duration', total)
    results = {}
    try:
        for label, start in phases:
            extra, measured = start()
            try:
                results[label] = result_of(measured, duration + warmup + 120.0)
            finally:
                for proc in extra:
                    proc.stop() if hasattr(proc, 'stop') else proc.kill()
    finally:
        pub.kill()
        pub.communicate()
    return results


def graph_config(config, duration, warmup, workdir, size='', transport='raw', quality=90):
    """
    Measure one ``NxWxH@RATE`` configuration; returns the results by phase.

    ``size`` ``'WxH'`` sets the panorama size; empty: the node's default (from the rig).
    ``transport`` ``compressed``: the cameras publish image_transport's JPEG (of the rig's
    views of a scene) and the node takes them with ``image_transport:=compressed``.
    """
    from graph_harness.graph import NodeProcess
    from accelcal_ros.camera.rig import ring_rig, save_rig

    count, size = config.split('x', 1)
    size, rate = size.split('@')
    width, height = (int(v) for v in size.split('x'))
    count, rate = int(count), float(rate)
    rig_path = os.path.join(workdir, f'rig_{count}x{width}x{height}.yaml')
    save_rig(rig_path, ring_rig(count, width, height, 1100.0 * width / 1280.0, 36.0))
    topics = ','.join(f'cam{i}/image_raw' for i in range(count))
    common = ['--topics', topics, '--duration', duration, '--warmup', warmup,
              '--transport', transport]

    def bare_phase(raw):
        return lambda: ([], child('bare', *common, *(['--raw'] if raw else [])))

    def node_phase(diag_only=False):
        params = {'rig_file': rig_path, 'camera_topics': topics.split(','),
                  'image_transport': transport}
        if size:
            params['width'], params['height'] = (int(v) for v in size.split('x'))
        node = NodeProcess('stitcher', params, log_dir=workdir)
        return [node], child('sink', '--topic', 'panorama', '--msg-type', 'image',
                             '--diag-prefix', 'stitcher: panorama', '--duration', duration,
                             '--warmup', warmup, *(['--diag-only'] if diag_only else []))

    options = ['--topics', topics, '--width', width, '--height', height, '--rate', rate,
               '--encoding', 'bgr8', '--wobble-deg', 2.0, '--pitch-deg', 10.0,
               '--transport', transport, '--jpeg-quality', quality,
               *(['--rig', rig_path] if transport == 'compressed' else [])]
    return run_graph(options, [('floor (deserialised)', bare_phase(False)),
                               ('floor (raw)', bare_phase(True)),
                               ('stitcher', node_phase),
                               ('stitcher, no subscriber', lambda: node_phase(True))],
                     duration, warmup)


def _figure(value):
    """Return a figure as a table shows it: 2 decimals (3 significant digits below 1)."""
    if isinstance(value, float):
        return f'{value:.3g}' if abs(value) < 1.0 else f'{value:.2f}'
    return str(value)


def report(config, results, target_fps=None, ratio=0.9, what='panoramas', duration_s=None):
    """
    Print one configuration's figures against the targets, as an aligned table.

    A rate over a ``duration_s`` window is known to one frame in that window: the target
    counts as met when the node fell short of it by less than one frame.
    """
    floor = results.get('floor (deserialised)', {})
    floor_raw = results.get('floor (raw)', {})
    node = results.get('stitcher', results.get('p2p', {}))
    print(f'\n{config}')
    keys = [k for k in ('sets_per_s', 'frames_per_s', 'per_s', 'latency_ms', 'latency_p90_ms',
                        'node_input_frames_per_s', 'waited_s')
            if any(k in res for res in results.values())]
    widths = [max(len(k), 8) + 2 for k in keys]
    print(f'  {"phase":24s}' + ''.join(f'{k:>{w}s}' for k, w in zip(keys, widths)))
    for label, res in results.items():
        cells = [_figure(res[k]) if k in res else '-' for k in keys]
        print(f'  {label:24s}' + ''.join(f'{c:>{w}s}' for c, w in zip(cells, widths)))
        if 'error' in res:
            print(f'  {"":24s}error: {res["error"]}')
    if 'per_s' not in node or 'sets_per_s' not in floor:
        print('  incomplete run: see the errors above')
        return
    best_floor = max(floor['sets_per_s'], floor_raw.get('sets_per_s', 0.0))
    print(f'  {what} per second {node["per_s"]:.2f}, floor {floor["sets_per_s"]:.2f} '
          f'(raw {floor_raw.get("sets_per_s", math.nan):.2f}) complete sets/s: ratio '
          f'{node["per_s"] / max(floor["sets_per_s"], 1e-9):.2f} (target >= {ratio}; vs '
          f'the best floor {node["per_s"] / max(best_floor, 1e-9):.2f}); latency median '
          f'{node["latency_ms"]:.0f} ms, p90 {node["latency_p90_ms"]:.0f} ms')
    alone = results.get('stitcher, no subscriber', {})
    if 'per_s' in alone:
        print(f'  without a panorama subscriber the node made {alone["per_s"]:.2f} panoramas '
              'per second (its diagnostics): the rest is the transport of the output')
    if target_fps:
        slack = 1.0 / duration_s if duration_s else 0.0   # one frame over the window
        met = node['per_s'] + slack >= target_fps - 1e-9
        print(f'  target {target_fps:g} fps: {node["per_s"]:.2f} measured over '
              f'{duration_s or "?"} s (+- one frame: {slack:.2f} fps): '
              f'{"met" if met else "NOT met"}')


# -- per-stage cost in one process ------------------------------------------------------
def stages(config, repeats, size_option=''):
    """Print each stage's cost per frame set, the node's path before and now."""
    import cv2
    from accelcal_ros.camera.rig import ring_rig
    from accelcal_ros.panorama.params import panorama_size_from_focal, reference_focal_px
    from accelcal_ros.panorama.projection import PanoramaGeometry
    from accelcal_ros.panorama.stitch import Stitcher
    from accelcal_ros.rosutil.images import array_to_image_msg, image_cdr, image_from_cdr
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import Image

    cv2.setNumThreads(2)
    count, size = config.split('x', 1)
    size = size.split('@')[0]
    width, height = (int(v) for v in size.split('x'))
    count = int(count)
    rig = ring_rig(count, width, height, 1100.0 * width / 1280.0, 36.0)
    out_w, out_h = (int(v) for v in size_option.split('x')) if size_option else \
        panorama_size_from_focal(reference_focal_px(rig), 180.0, 120.0)
    stitcher = Stitcher(rig, PanoramaGeometry(out_w, out_h))
    rng = np.random.default_rng(0)
    wire = [serialize_message(array_to_image_msg(
        rng.integers(0, 256, (height, width, 3), dtype=np.uint8), 'bgr8', Image))
        for _ in range(count)]
    times = {}

    def timed(name, func, *a):
        start = time.perf_counter()
        out = func(*a)
        times.setdefault(name, []).append(time.perf_counter() - start)
        return out

    def old_convert(msg):
        buf = np.frombuffer(bytes(msg.data), np.uint8)       # as the node did before
        return np.ascontiguousarray(buf.reshape(msg.height, msg.step)[:, :width * 3]
                                    ).reshape(msg.height, width, 3)

    def old_publish(panorama):
        return serialize_message(array_to_image_msg(panorama, 'bgr8', Image))

    for k in range(repeats):
        msgs = [timed('before: deserialise', lambda: [deserialize_message(w, Image)
                                                      for w in wire])][0]
        images = timed('before: convert (copies)', lambda: [old_convert(m) for m in msgs])
        views = timed('now: parse + views', lambda: [image_from_cdr(w)[1] for w in wire])
        timed('copy into the mosaic', lambda: [stitcher.set_image(i, v)
                                               for i, v in enumerate(views)])
        timed('lookup rebuild', stitcher.set_attitude, math.radians(0.1 * k),
              math.radians(10.0), True)
        panorama = timed('remap', stitcher.render)
        timed('before: build + serialise', old_publish, panorama)
        timed('now: serialise (image_cdr)', image_cdr, panorama, 'bgr8', 1, 2, 'panorama')
        timed('JPEG (compressed_output)', cv2.imencode, '.jpg', panorama,
              [cv2.IMWRITE_JPEG_QUALITY, 80])
        del images
    print(f'\nper frame set, {config}, into {out_w}x{out_h} (median of {repeats}, one '
          'process):')
    for name, values in times.items():
        print(f'  {name:30s} {1e3 * statistics.median(values):7.1f} ms')


def main():
    """Parse the options; run a child role or the whole benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--role', default='main',
                        choices=('main', 'publisher', 'bare', 'sink'))
    parser.add_argument('--duration', type=float, default=10.0, help='seconds measured')
    parser.add_argument('--warmup', type=float, default=3.0, help='seconds not counted')
    parser.add_argument('--configs', nargs='+', default=list(CONFIGS),
                        help='NxWIDTHxHEIGHT@RATE_HZ (cameras, size, rate)')
    parser.add_argument('--stages', action='store_true', help='per-stage costs only')
    parser.add_argument('--size', default='', help='panorama WIDTHxHEIGHT (e.g. 3600x2400, '
                        'the fixed size before issue 16); default: that of the node, from the rig')
    parser.add_argument('--repeats', type=int, default=10, help='sets for --stages')
    parser.add_argument('--shm-mb', type=float, default=0.0,
                        help='run every process with a Fast DDS shared-memory segment of '
                        'this size (MB; e.g. 128); 0: the middleware default (0.5 MB)')
    parser.add_argument('--hosts', type=int, choices=(1, 2), default=1,
                        help='2: cameras on host A, subscribers on host B across a shaped '
                        'link, raw against compressed (network namespaces; root)')
    parser.add_argument('--link-rate', default='1gbit', help='--hosts 2: tc rate of the link')
    parser.add_argument('--transports', nargs='+', default=['raw', 'compressed'],
                        choices=('raw', 'compressed'), help='--hosts 2: camera transports')
    parser.add_argument('--transport', default='raw', choices=('raw', 'compressed'))
    parser.add_argument('--rig', default='')
    parser.add_argument('--jpeg-quality', type=int, default=90)
    parser.add_argument('--topics', default='')
    parser.add_argument('--width', type=int, default=1280)
    parser.add_argument('--height', type=int, default=960)
    parser.add_argument('--rate', type=float, default=10.0)
    parser.add_argument('--encoding', default='bgr8')
    parser.add_argument('--image-npy', default='')
    parser.add_argument('--camera-info', default='')
    parser.add_argument('--roll-deg', type=float, default=0.0)
    parser.add_argument('--pitch-deg', type=float, default=0.0)
    parser.add_argument('--wobble-deg', type=float, default=0.0)
    parser.add_argument('--pub-depth', type=int, default=5)
    parser.add_argument('--sub-depth', type=int, default=2)
    parser.add_argument('--raw', action='store_true')
    parser.add_argument('--diag-only', action='store_true')
    parser.add_argument('--topic', default='panorama')
    parser.add_argument('--msg-type', default='image', choices=('image', 'pose'))
    parser.add_argument('--diag-prefix', default='stitcher: panorama')
    args = parser.parse_args()
    if args.role != 'main':
        return {'publisher': publisher, 'bare': bare, 'sink': sink}[args.role](args)
    if args.stages:
        for config in args.configs:
            stages(config, args.repeats, args.size)
        return 0
    if args.hosts == 2:
        from panorama_hosts import two_hosts_main

        return two_hosts_main(args, sys.modules[__name__])
    holder = isolated_domain()
    print(f'stitcher in a ROS graph, {args.duration:g} s per phase (ROS_DOMAIN_ID '
          f'{os.environ.get("ROS_DOMAIN_ID", "0")}); panorama size '
          f'{args.size or "the default (from the rig)"}; load average '
          f'{" ".join(f"{x:.2f}" for x in os.getloadavg())}; indicative on a loaded machine')
    with tempfile.TemporaryDirectory() as workdir:
        if args.shm_mb:
            print(f'Fast DDS profile {use_fastdds_profile(args.shm_mb, workdir)}: shared '
                  f'memory segment {args.shm_mb:g} MB')
        for config in args.configs:
            results = graph_config(config, args.duration, args.warmup, workdir, args.size,
                                   args.transport, args.jpeg_quality)
            fps = float(config.split('@')[1]) if config.startswith('5x640x480') else None
            report(config, results, target_fps=fps, duration_s=args.duration)
    del holder
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
