"""
``bench_panorama_graph.py --hosts 2``: the cameras on one host, the stitcher on another.

Two network namespaces joined by a veth pair (:mod:`graph_harness.netns`), each direction
shaped to ``--link-rate`` (tc tbf, 1 Gbit/s by default). Host A runs the benchmark's
camera publisher (the rig's rendered views of a scene, so that JPEG sizes are real; one
stamp per set) and the attitude; host B runs, one after the other, the bare subscriber
(complete frame sets/s, no processing), the stitcher with a panorama subscriber
(panoramas/s) and the stitcher alone (its rate from /diagnostics). Both transports:
``raw`` (sensor_msgs/Image) and ``compressed`` (image_transport's JPEG on
``<topic>/compressed``, the stitcher with ``image_transport:=compressed``). Host A's
processes use Fast DDS over UDP only (another computer: no shared memory with B); host
B's use the shipped large shared-memory segment plus UDP, both with 4 MB socket buffers
(``net.core.rmem_max`` here). Printed: sets/s, panoramas/s, the ratio to the bare
subscriber, the link's throughput, the bound the link puts on raw frames, and the decode
cost per set (serial, and in the nodes' decode pool).
"""
import math
import os
import statistics
import tempfile
import time

import numpy as np

PROFILE = """<?xml version="1.0" encoding="UTF-8"?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <transport_descriptors>
    <transport_descriptor>
      <transport_id>shm_large</transport_id>
      <type>SHM</type>
      <segment_size>134217728</segment_size>
    </transport_descriptor>
    <transport_descriptor>
      <transport_id>udp</transport_id>
      <type>UDPv4</type>
      <sendBufferSize>4194304</sendBufferSize>
      <receiveBufferSize>4194304</receiveBufferSize>
    </transport_descriptor>
  </transport_descriptors>
  <participant profile_name="bench" is_default_profile="true">
    <rtps>
      <userTransports>
{transports}
      </userTransports>
      <useBuiltinTransports>false</useBuiltinTransports>
    </rtps>
  </participant>
</profiles>
"""


def rendered_views(rig_path, encoding='bgr8'):
    """Return the rig's noisy views of the test scene (roll 2, pitch 10 deg), bgr8 or mono8."""
    import cv2
    from accelcal_ros.camera.rig import load_rig
    from accelcal_ros.panorama import render

    rig = load_rig(rig_path)
    scene = render.make_scene(3600, 1800, seed=2)
    views = render.render_camera_views(scene, rig, math.radians(2.0), math.radians(10.0))
    rng = np.random.default_rng(3)           # sensor noise (sigma 2 levels): real JPEG sizes
    views = [np.clip(v + rng.normal(0.0, 2.0, v.shape), 0, 255).astype(np.uint8)
             for v in views]
    if encoding == 'mono8':
        return [cv2.cvtColor(v, cv2.COLOR_BGR2GRAY) for v in views]
    return views


def decode_cost(views, quality, repeats=10):
    """JPEG size per frame and decode time per set: serial, and in a DecodePool."""
    import threading

    from accelcal_ros.rosutil.compressed import decode_compressed, encode_compressed
    from accelcal_ros.rosutil.decode_pool import DecodePool

    frames = [encode_compressed(v, 'bgr8', 'jpeg', quality) for v in views]
    serial, pooled = [], []
    pool = DecodePool(len(frames))
    try:
        for _ in range(repeats):
            start = time.process_time()     # CPU time: what a set costs, whatever the load
            for fmt, data in frames:
                decode_compressed(data, fmt)
            serial.append(time.process_time() - start)
            done = threading.Semaphore(0)
            start = time.perf_counter()
            for i, (fmt, data) in enumerate(frames):
                pool.submit(i, lambda f, d: (decode_compressed(d, f), done.release()), fmt,
                            data)
            for _ in frames:
                done.acquire()
            pooled.append(time.perf_counter() - start)
    finally:
        pool.close()
    return {'jpeg_kb': statistics.mean(len(d) for _, d in frames) / 1e3,
            'serial_ms': 1e3 * statistics.median(serial),
            'pool_ms': 1e3 * statistics.median(pooled)}


def _host_prefix(hosts, host, profile):
    return [*hosts.prefix(host), 'env', f'FASTRTPS_DEFAULT_PROFILES_FILE={profile}']


def run_transport(bench, hosts, transport, rig_path, topics, size, rate, args, profiles):
    """Run the phases of one transport; returns ``{phase: result}`` with link MB/s."""
    from graph_harness.graph import NodeProcess

    width, height = size
    common = ['--topics', ','.join(topics), '--duration', args.duration,
              '--warmup', args.warmup, '--transport', transport]
    prefix_b = _host_prefix(hosts, 'b', profiles['b'])
    env_b = {'FASTRTPS_DEFAULT_PROFILES_FILE': profiles['b']}
    workdir = os.path.dirname(rig_path)

    def node(diag_only):
        params = {'rig_file': rig_path, 'camera_topics': topics, 'image_transport': transport}
        proc = NodeProcess('stitcher', params, log_dir=workdir, prefix=hosts.prefix('b'),
                           env=env_b, name=f'stitcher_{transport}')
        sink = bench.child('sink', '--topic', 'panorama', '--msg-type', 'image',
                           '--diag-prefix', 'stitcher: panorama', '--duration',
                           args.duration, '--warmup', args.warmup,
                           *(['--diag-only'] if diag_only else []), prefix=prefix_b)
        return [proc], sink

    phases = [('bare subscriber', lambda: ([], bench.child('bare', *common, '--raw',
                                                           prefix=prefix_b))),
              ('stitcher', lambda: node(False)),
              ('stitcher, no subscriber', lambda: node(True))]
    total = len(phases) * (args.duration + args.warmup + 40.0) + 10.0
    publisher = bench.child(
        'publisher', *common[:2], '--width', width, '--height', height, '--rate', rate,
        '--encoding', 'bgr8', '--rig', rig_path, '--jpeg-quality', args.jpeg_quality,
        '--wobble-deg', 2.0, '--pitch-deg', 10.0, '--duration', total, '--transport',
        transport, prefix=_host_prefix(hosts, 'a', profiles['a']))
    results = {}
    try:
        for label, start in phases:
            extra, measured = start()
            before, t0 = hosts.link_bytes('b'), time.monotonic()
            try:
                results[label] = bench.result_of(measured, args.duration + args.warmup + 120)
            finally:
                after, t1 = hosts.link_bytes('b'), time.monotonic()
                for proc in extra:
                    proc.stop()
            results[label]['link_mb_s'] = (after[1] - before[1]) / 1e6 / max(t1 - t0, 1e-9)
    finally:
        publisher.kill()
        publisher.communicate()
    return results


def _rate_bits(text):
    units = {'kbit': 1e3, 'mbit': 1e6, 'gbit': 1e9, 'bit': 1.0}
    for unit, factor in units.items():
        if text.lower().endswith(unit):
            return float(text[:-len(unit)]) * factor
    return float(text)


def report(config, rate, size, count, cost, results, link_rate):
    """Print one configuration's table and the figures against the targets."""
    raw_set_mb = count * size[0] * size[1] * 3 / 1e6
    link_mb_s = _rate_bits(link_rate) / 8e6
    print(f'\n{config} across a {link_rate} link: raw {raw_set_mb:.1f} MB per set '
          f'({raw_set_mb * rate:.0f} MB/s at {rate:g} Hz; the link carries {link_mb_s:.0f} '
          f'MB/s = at most {link_mb_s / raw_set_mb:.1f} raw sets/s); JPEG '
          f'{cost["jpeg_kb"]:.0f} kB per frame ({count * cost["jpeg_kb"] * rate / 1e3:.1f} '
          f'MB/s)')
    print(f'  decode per set of {count} JPEGs: {cost["serial_ms"]:.1f} ms of CPU, '
          f'{cost["pool_ms"]:.1f} ms wall in the decode pool ({count} threads)')
    print(f'  {"transport":11s} {"bare sets/s":>12s} {"panoramas/s":>12s} {"ratio":>6s} '
          f'{"alone/s":>8s} {"link MB/s*":>10s} {"decode ms":>10s}')
    for transport, res in results.items():
        bare = res.get('bare subscriber', {})
        node = res.get('stitcher', {})
        alone = res.get('stitcher, no subscriber', {})
        sets = bare.get('sets_per_s', math.nan)
        pans = node.get('per_s', math.nan)
        diag = alone.get('diagnostics', {}) or node.get('diagnostics', {})
        print(f'  {transport:11s} {sets:12.2f} {pans:12.2f} {pans / max(sets, 1e-9):6.2f} '
              f'{alone.get("per_s", math.nan):8.2f} {bare.get("link_mb_s", math.nan):10.1f} '
              f'{diag.get("decode_ms", "-"):>10s}')
        for label, value in res.items():
            if 'error' in value:
                print(f'    {label}: {value["error"]}')
    comp = results.get('compressed', {})
    if 'sets_per_s' in comp.get('bare subscriber', {}) and 'per_s' in comp.get('stitcher', {}):
        print('  * received on B over the bare subscriber phase (start-up included)')
        ratio = comp['stitcher']['per_s'] / max(comp['bare subscriber']['sets_per_s'], 1e-9)
        print(f'  compressed: stitcher / bare subscriber on B = {ratio:.2f} (target >= 0.9: '
              f'{"met" if ratio >= 0.9 else "NOT met"})')


def two_hosts_main(args, bench):
    """Run every configuration across two hosts (see the module); returns the exit code."""
    from graph_harness.netns import TwoHosts, unavailable
    from accelcal_ros.camera.rig import ring_rig, save_rig

    reason = unavailable()
    if reason:
        print(f'--hosts 2 cannot run here: {reason}')
        return 1
    holder = bench.isolated_domain()
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'SUBNET'
    print(f'stitcher across two hosts (network namespaces, link {args.link_rate}), '
          f'{args.duration:g} s per phase (ROS_DOMAIN_ID {os.environ.get("ROS_DOMAIN_ID")}); '
          f'load average {" ".join(f"{x:.2f}" for x in os.getloadavg())}; '
          f'{os.cpu_count()} CPUs; indicative on a loaded machine')
    with tempfile.TemporaryDirectory() as workdir:
        profiles = {}
        for host, transports in (('a', ['udp']), ('b', ['shm_large', 'udp'])):
            path = os.path.join(workdir, f'fastdds_host_{host}.xml')
            with open(path, 'w') as handle:
                handle.write(PROFILE.replace('{transports}', '\n'.join(
                    f'        <transport_id>{t}</transport_id>' for t in transports)))
            profiles[host] = path
        for config in args.configs:
            count, rest = config.split('x', 1)
            size_text, rate = rest.split('@')
            size = tuple(int(v) for v in size_text.split('x'))
            count, rate = int(count), float(rate)
            rig_path = os.path.join(workdir, f'rig_{count}x{size[0]}x{size[1]}.yaml')
            save_rig(rig_path, ring_rig(count, size[0], size[1], 1100.0 * size[0] / 1280.0,
                                        36.0))
            cost = decode_cost(rendered_views(rig_path), args.jpeg_quality)
            topics = [f'cam{i}/image_raw' for i in range(count)]
            hosts = TwoHosts()
            results = {}
            try:
                hosts.shape(args.link_rate)
                for transport in args.transports:
                    results[transport] = run_transport(bench, hosts, transport, rig_path,
                                                       topics, size, rate, args, profiles)
            finally:
                hosts.remove()
            report(config, rate, size, count, cost, results, args.link_rate)
    del holder
    return 0


if __name__ == '__main__':
    print('run: python benchmarks/bench_panorama_graph.py --hosts 2')
    raise SystemExit(2)
