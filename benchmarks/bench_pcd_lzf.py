"""
PCD ``binary_compressed`` read/write time of one VLP-16 scan: C LZF vs the pure-Python one.

One revolution of the simulated VLP-16 (28,800 points: x y z intensity ring time) is written
and read with each LZF backend of :mod:`accelcal_ros.lidar.lzf` (``c``: liblzf through the
``python-neo-lzf`` package; ``python``: the numpy-assisted fallback); each figure is the
median of ``--repeats`` runs. Also checks that each backend reads the other's file.

Run:  source tools/env.sh && python benchmarks/bench_pcd_lzf.py [--repeats 5]
"""
import argparse
import os
import statistics
import tempfile
import time

from accelcal_ros.lidar import lzf
from accelcal_ros.lidar import scanner_sim as sim
from accelcal_ros.lidar.pcd import read_pcd, write_pcd
import numpy as np


def _median_ms(function, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return 1e3 * statistics.median(times)


def main():
    """Print read/write times per backend and the speed-up."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--repeats', type=int, default=5, help='runs per figure (median)')
    args = parser.parse_args()
    cloud = sim.simulate_protocol(sim.default_boresight(), tilts_deg=[(0, 0)])[0].cloud
    backends = ['python'] + (['c'] if lzf.c_available() else [])
    print(f'PCD binary_compressed, one scan of {len(cloud)} points '
          f'({cloud.dtype.itemsize} bytes each), median of {args.repeats}')
    figures = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in backends:
            os.environ['ACCELCAL_LZF'] = name
            path = os.path.join(tmp, f'scan_{name}.pcd')
            write_ms = _median_ms(lambda: write_pcd(path, cloud, 'binary_compressed'),
                                  args.repeats)
            read_ms = _median_ms(lambda: read_pcd(path), args.repeats)
            figures[name] = (read_ms, write_ms)
            print(f'  {name:6}: read {read_ms:8.2f} ms, write {write_ms:8.2f} ms, '
                  f'{os.path.getsize(path) / 1024:7.1f} kB')
        for reader in backends:  # each backend reads every backend's file
            os.environ['ACCELCAL_LZF'] = reader
            for writer in backends:
                back, _ = read_pcd(os.path.join(tmp, f'scan_{writer}.pcd'))
                for field in cloud.dtype.names:
                    np.testing.assert_array_equal(back[field], cloud[field])
        os.environ.pop('ACCELCAL_LZF', None)
    print(f'  cross-decompression: each backend reads the files of all '
          f'({", ".join(backends)}): identical')
    if 'c' in figures:
        (pr, pw), (cr, cw) = figures['python'], figures['c']
        print(f'  C is {pr / cr:.0f}x faster to read, {pw / cw:.0f}x faster to write')
    else:
        print('  python-neo-lzf not installed: only the pure-Python backend was measured')


if __name__ == '__main__':
    main()
