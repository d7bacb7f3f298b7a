"""
Bag reading throughput and peak memory on a bag larger than 1 GB, beside the same data as CSV/PCD.

Run:  source tools/env.sh && python benchmarks/bench_recording.py [--size-gb 1.1] [--quick]

Generates, streaming, into a temporary directory (deleted at the end unless ``--keep``):
a rosbag2 mcap (or ``--format sqlite3|ros1``) with ``/imu/data`` (sensor_msgs/Imu, 200 Hz)
and ``/velodyne_points`` (sensor_msgs/PointCloud2, 10 Hz, one simulated VLP-16 revolution
per scan, about 630 kB), and the same data as one IMU CSV and one binary PCD per scan.
Each measurement runs in a fresh process, so its peak RSS (``resource.getrusage``
``ru_maxrss``) is its own:

- ``imu-bag``: :func:`accelcal_ros.recording.streams.read_imu` (every Imu deserialised
  into arrays), ``imu-csv``: :func:`accelcal_ros.lidar.imu_log.read_imu_csv`;
- ``points-bag``: every PointCloud2 streamed and converted to a structured array
  (:func:`accelcal_ros.recording.convert.cloud_array`), ``points-pcd``: every PCD read.

Prints messages/s, MB/s (bytes of the bag's message payloads or of the files) and peak
RSS per measurement. A bag is never loaded whole: the points-bag peak stays near one
scan plus the interpreter, whatever the bag size.
"""
import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

IMU_TOPIC = '/imu/data'
POINTS_TOPIC = '/velodyne_points'
IMU_RATE_HZ = 200.0
SCAN_RATE_HZ = 10.0


def _scan():
    from accelcal_ros.lidar import scanner_sim as sim

    protocol = sim.simulate_protocol(sim.default_boresight(), seed=0, still_s=0.1,
                                     tilts_deg=[(0.0, 0.0)])
    return protocol[0].cloud


def generate(directory, size_gb, fmt):
    """Write the bag and the CSV/PCD copies; returns a dict of counts and paths."""
    from accelcal_ros.lidar.pcd import write_pcd
    from accelcal_ros.recording.writer import BagWriter, sensor_data_qos

    cloud = _scan()
    scan_bytes = cloud.dtype.itemsize * len(cloud)
    n_scans = int(np.ceil(size_gb * 1e9 / scan_bytes))
    per_scan = int(IMU_RATE_HZ / SCAN_RATE_HZ)
    bag = os.path.join(directory, 'big.bag' if fmt == 'ros1' else 'big')
    pcd_dir = os.path.join(directory, 'pcd')
    os.makedirs(pcd_dir)
    csv = os.path.join(directory, 'imu.csv')
    rng = np.random.default_rng(0)
    t0_ns = 1_700_000_000 * 10**9
    start = time.perf_counter()
    with BagWriter(bag, fmt) as writer, open(csv, 'w') as imu_csv:
        writer.add_topic(IMU_TOPIC, 'sensor_msgs/Imu', [sensor_data_qos()])
        writer.add_topic(POINTS_TOPIC, 'sensor_msgs/PointCloud2', [sensor_data_qos()])
        imu_csv.write('t,ax,ay,az,gx,gy,gz\n')
        for k in range(n_scans):
            for j in range(per_scan):
                t_s = (k * per_scan + j) / IMU_RATE_HZ
                ns = t0_ns + int(round(t_s * 1e9))
                accel = np.array([0.0, 0.0, 9.81]) + rng.normal(0, 0.02, 3)
                gyro = rng.normal(0, 0.002, 3)
                writer.write(IMU_TOPIC, ns, writer.imu_message(ns, accel, 'imu_link', gyro))
                imu_csv.write(f'{t_s:.6f},' + ','.join(f'{v:.9g}' for v in accel) + ','
                              + ','.join(f'{v:.9g}' for v in gyro) + '\n')
            ns = t0_ns + int(round(k / SCAN_RATE_HZ * 1e9))
            writer.write(POINTS_TOPIC, ns, writer.pointcloud2_message(ns, cloud, 'velodyne'))
            write_pcd(os.path.join(pcd_dir, f'scan{k:06d}.pcd'), cloud, 'binary')
    elapsed = time.perf_counter() - start
    return {'bag': bag, 'csv': csv, 'pcd_dir': pcd_dir, 'scans': n_scans,
            'imu': n_scans * per_scan, 'scan_bytes': scan_bytes, 'write_s': elapsed}


def _du(path):
    if os.path.isfile(path):
        return os.path.getsize(path)
    return sum(os.path.getsize(os.path.join(d, f)) for d, _, fs in os.walk(path) for f in fs)


def run_phase(phase, info):
    """Do one measurement in this process; returns a dict (time, counts, bytes, peak RSS)."""
    start = time.perf_counter()
    count, nbytes = 0, 0
    if phase == 'imu-bag':
        from accelcal_ros.recording.bag import BagReader
        from accelcal_ros.recording.streams import read_imu

        with BagReader(info['bag']) as bag:
            imu = read_imu(bag, IMU_TOPIC, '--imu')
            first = next(iter(bag.messages([IMU_TOPIC], decode=())))
        count = len(imu.t)
        nbytes = count * len(first.raw)   # every Imu has the same serialised size here
    elif phase == 'imu-csv':
        from accelcal_ros.lidar.imu_log import read_imu_csv

        log = read_imu_csv(info['csv'])
        count, nbytes = len(log.t), os.path.getsize(info['csv'])
    elif phase == 'points-bag':
        from accelcal_ros.recording import convert
        from accelcal_ros.recording.bag import BagReader

        with BagReader(info['bag']) as bag:
            for message in bag.messages([POINTS_TOPIC]):
                convert.cloud_array(message.msg)   # the conversion every command does
                count += 1
                nbytes += len(message.raw)
    elif phase == 'points-pcd':
        from accelcal_ros.lidar.pcd import read_pcd

        for name in sorted(os.listdir(info['pcd_dir'])):
            path = os.path.join(info['pcd_dir'], name)
            read_pcd(path)
            count += 1
            nbytes += os.path.getsize(path)
    elapsed = time.perf_counter() - start
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return {'phase': phase, 'seconds': elapsed, 'messages': count, 'bytes': nbytes,
            'peak_rss_mb': peak_mb}


def main():
    """Generate, measure each phase in a child process, print the table, clean up."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--size-gb', type=float, default=1.1, help='point payload, GB')
    parser.add_argument('--quick', action='store_true', help='0.1 GB')
    parser.add_argument('--format', choices=('mcap', 'sqlite3', 'ros1'), default='mcap')
    parser.add_argument('--keep', action='store_true', help='keep the generated files')
    parser.add_argument('--phase', help=argparse.SUPPRESS)
    parser.add_argument('--info', help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.phase:
        print(json.dumps(run_phase(args.phase, json.loads(args.info))))
        return 0
    size = 0.1 if args.quick else args.size_gb
    directory = tempfile.mkdtemp(prefix='bench_recording_', dir='/tmp')
    try:
        info = generate(directory, size, args.format)
        bag_mb = _du(info['bag']) / 1e6
        files_mb = (_du(info['pcd_dir']) + os.path.getsize(info['csv'])) / 1e6
        print(f'generated in {info["write_s"]:.1f} s: {args.format} bag {bag_mb:.0f} MB '
              f'({info["scans"]} PointCloud2 of {info["scan_bytes"] / 1e3:.0f} kB, '
              f'{info["imu"]} Imu); CSV + PCD {files_mb:.0f} MB')
        print(f'{"phase":<11} {"messages":>9} {"s":>8} {"msg/s":>10} {"MB/s":>8} '
              f'{"peak RSS MB":>12}')
        for phase in ('imu-bag', 'imu-csv', 'points-bag', 'points-pcd'):
            out = subprocess.run([sys.executable, __file__, '--phase', phase, '--info',
                                  json.dumps(info)], capture_output=True, text=True,
                                 check=True, env=dict(os.environ, ACCELCAL_PROGRESS='0'))
            r = json.loads(out.stdout.strip().splitlines()[-1])
            print(f'{phase:<11} {r["messages"]:>9} {r["seconds"]:>8.2f} '
                  f'{r["messages"] / r["seconds"]:>10.0f} '
                  f'{r["bytes"] / 1e6 / r["seconds"]:>8.1f} {r["peak_rss_mb"]:>12.0f}')
    finally:
        if args.keep:
            print(f'kept {directory}')
        else:
            shutil.rmtree(directory, ignore_errors=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
