"""
Throughput of ``accelcal georeference BAG --navsat ... -o OUT.laz`` (VLP-16 scans -> UTM LAZ).

A simulated INS recording (NavSatFix + Odometry at 100 Hz, VLP-16 scans at 10 Hz, 28 800
points a revolution = 288 000 points/s, the sensor's single-return rate) is georeferenced
into UTM 37N and written as LAZ (lazrs) and LAS. The figure: points per second of wall
time for the whole command (bag read, per-point pose, PROJ, LAZ), and the stages alone.
The target is 1 M points/s (three VLP-16s in real time) on 2 cores. Wall time on a
shared machine says little: the table also gives the CPU time of the process (all its
threads) and ``2-core bound`` = points / max(wall, CPU / 2), the rate two free cores give
when the work keeps both busy (the LAZ writer compresses on its own thread while the
next batch is georeferenced; PROJ and numpy run without the GIL).

Run:  source tools/env.sh && python benchmarks/bench_georef_map.py [--seconds 10]
"""
import argparse
import os
import tempfile
import time

from accelcal_ros.cli import main
from accelcal_ros.fileio import write_text_atomic
from accelcal_ros.lidar.cloud import xyz
from accelcal_ros.lidar.geo_sim import simulate_drive, vlp16_scans, write_drive_bag
from accelcal_ros.lidar.geotraj import MapGeoreferencer
from accelcal_ros.lidar.las import LasCloudWriter
from accelcal_ros.textformats import dump_yaml
import numpy as np


def _timed(label, func, points, rows):
    start, cpu = time.perf_counter(), time.process_time()
    result = func()
    rows.append((label, points, time.perf_counter() - start, time.process_time() - cpu))
    return result


def main_bench():
    """Build the recording, time the command and its stages, print a table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--seconds', type=float, default=10.0, help='recording length (s)')
    args = parser.parse_args()
    drive = simulate_drive(duration_s=args.seconds + 1.0, targets=10)
    cloud = vlp16_scans(drive, int(args.seconds * 10))
    n = len(cloud)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        bag = os.path.join(tmp, 'ins')
        write_drive_bag(bag, 'mcap', drive, cloud=cloud)
        bs = os.path.join(tmp, 'bs.yaml')
        write_text_atomic(bs, dump_yaml({'R': drive.boresight.reshape(-1).tolist()}))
        for ext in ('laz', 'las'):
            out = os.path.join(tmp, f'out.{ext}')
            argv = ['georeference', bag, '--navsat', '/gnss/fix', '--odom', '/ins/odom',
                    '--boresight', bs, '-o', out]
            _timed(f'bag -> {ext.upper()} (whole command)', lambda: main(argv), n, rows)
            size = os.path.getsize(out)
            print(f'{ext}: {size / n:.1f} bytes/point')
        geo = MapGeoreferencer(drive.trajectory, drive.boresight, drive.lever_arm_m)
        pts, times = xyz(cloud), cloud['timestamp']
        from accelcal_ros.lidar.georef import georeference

        ecef, keep, _ = _timed('pose + ECEF (georef core)', lambda: georeference(
            pts, times, geo.interp, geo.boresight, geo.lever_arm_m), n, rows)
        enh = _timed('ECEF -> UTM (PROJ)', lambda: geo.projection.from_ecef(ecef), n, rows)

        def write(ext):
            with LasCloudWriter(os.path.join(tmp, f'w.{ext}'), geo.projection.wkt(),
                                geo.origin_m, True, True) as writer:
                for a in range(0, n, 1 << 18):
                    writer.write(enh[a:a + (1 << 18)], times[a:a + (1 << 18)],
                                 cloud['intensity'][a:a + (1 << 18)],
                                 cloud['ring'][a:a + (1 << 18)])

        _timed('LAZ write (lazrs)', lambda: write('laz'), n, rows)
        _timed('LAS write', lambda: write('las'), n, rows)
    print(f'{n} points ({args.seconds:g} s of VLP-16), {os.cpu_count()} CPUs, load average '
          f'{os.getloadavg()[0]:.1f}')
    print(f'{"stage":<30} {"points":>10} {"wall s":>8} {"CPU s":>8} {"M pts/s wall":>13} '
          f'{"M pts/CPU-s":>12} {"2-core bound":>13} {"/ 1 M/s":>8}')
    for label, count, wall, cpu in rows:
        bound = count / max(cpu / 2.0, 1e-9) / 1e6
        print(f'{label:<30} {count:>10} {wall:>8.3f} {cpu:>8.3f} {count / wall / 1e6:>13.2f} '
              f'{count / cpu / 1e6:>12.2f} {bound:>13.2f} {bound:>8.2f}')
    assert np.isfinite(enh).all()


if __name__ == '__main__':
    main_bench()
