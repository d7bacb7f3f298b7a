"""
What OpenBLAS's threads cost a node: one ``N x 3`` by ``3 x 3`` product every 50 ms.

A node that transforms each incoming scan (``points @ R.T``, as ``cloud_assembler``'s
georeferencing does) at 20 scans a second. For each size ``N`` a fresh process (numpy
loaded anew, so OpenBLAS reads ``OPENBLAS_NUM_THREADS``) does 50 products 50 ms apart
with OpenBLAS's default thread count and with one thread (what the node executables
start with: :mod:`accelcal_ros.nodes`), and prints the product's median wall time and the
process's CPU time over the run as a share of one core: a share far above the product's
own time is OpenBLAS's threads spinning between products.
Run: ``python benchmarks/bench_blas_threads.py [--sizes 7200 30000 65536 262144]``.
"""
import argparse
import json
import os
import subprocess
import sys

from accelcal_ros.nodes import BLAS_THREADS_VARIABLE

CHILD = r"""
import json, statistics, sys, time
import numpy as np
n, cycles, period = int(sys.argv[1]), 50, 0.05
points = np.random.default_rng(0).random((n, 3))
rotation = np.eye(3)
walls = []
start_wall, start_cpu = time.perf_counter(), time.process_time()
for _ in range(cycles):
    t = time.perf_counter()
    points @ rotation.T
    walls.append(time.perf_counter() - t)
    time.sleep(period)
elapsed = time.perf_counter() - start_wall
print(json.dumps({'product_ms': 1e3 * statistics.median(walls),
                  'core_share': (time.process_time() - start_cpu) / elapsed}))
"""


def measure(n, threads):
    """Return the child's figures for ``n`` points, ``threads`` None = OpenBLAS's default."""
    env = dict(os.environ)
    env.pop(BLAS_THREADS_VARIABLE, None)
    if threads is not None:
        env[BLAS_THREADS_VARIABLE] = str(threads)
    done = subprocess.run([sys.executable, '-c', CHILD, str(n)], env=env, check=True,
                          capture_output=True, text=True)
    return json.loads(done.stdout)


def main():
    """Print one row per size: default threads against one thread."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--sizes', type=int, nargs='+', default=[7200, 30000, 65536, 262144])
    args = parser.parse_args()
    import numpy as np

    print(f'numpy {np.__version__}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; '
          'one product every 50 ms, 50 products')
    print(f'{"points":>8}  {"default: product":>17} {"CPU":>6}  {"1 thread: product":>18} '
          f'{"CPU":>6}  {"CPU ratio":>9}')
    for n in args.sizes:
        default, single = measure(n, None), measure(n, 1)
        print(f'{n:>8}  {default["product_ms"]:>14.2f} ms {100 * default["core_share"]:>5.0f}%'
              f'  {single["product_ms"]:>15.2f} ms {100 * single["core_share"]:>5.0f}%'
              f'  {default["core_share"] / max(single["core_share"], 1e-9):>8.1f}x')


if __name__ == '__main__':
    main()
