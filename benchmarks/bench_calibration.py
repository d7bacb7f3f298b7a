"""
Benchmark the calibration fit and the ``attitude`` node.

1. Fit time of :func:`~accelcal_ros.calibration.ellipsoid_fit.fit_ellipsoid` for K = 12,
   100 and 500 simulated positions (1 s each), diagonal and full model, the bare LM fit
   and the complete finish (outlier check and hold-out included).
2. The ``attitude`` node fed by ``imu_driver`` (sim) at 800 Hz, both as processes: the
   extra latency the attitude hop adds (receive time of ``attitude`` minus receive time
   of the ``imu/data_raw`` sample with the same stamp, both at one probe), the
   end-to-end latency (``attitude`` receive time - sample stamp), messages lost, and the
   node's CPU use (share of one core, from /proc). Run after ``source tools/env.sh``::

    python benchmarks/bench_calibration.py [--seconds 5] [--rate 800] [--repeat 20]
"""
import argparse
import os
import random
import shutil
import sys
import tempfile
import time

from accelcal_ros.calibration.coverage import recommended_directions
from accelcal_ros.calibration.ellipsoid_fit import fit_ellipsoid
from accelcal_ros.calibration.study import simulate_position_means
from accelcal_ros.sensor.model import paper_a_model
import numpy as np


def cpu_seconds(pid):
    """Return user + system CPU seconds of a process (from /proc)."""
    with open(f'/proc/{pid}/stat') as handle:
        fields = handle.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def bench_fit(repeat):
    """Print fit times (ms, median of ``repeat``)."""
    rng = np.random.default_rng(0)
    print(f'{"K":>5} {"model":>9} {"LM fit ms":>10} {"finish ms":>10} {"evaluations":>12}')
    for positions in (12, 100, 500):
        means, stds = simulate_position_means(paper_a_model(500),
                                              recommended_directions(positions), 100, rng)
        for model in ('diagonal', 'full'):
            bare, full, evaluations = [], [], 0
            for _ in range(repeat):
                start = time.perf_counter()
                fit = fit_ellipsoid(means, stds, model=model, drop_outliers=False,
                                    holdout=False)
                bare.append(time.perf_counter() - start)
                start = time.perf_counter()
                fit_ellipsoid(means, stds, model=model)
                full.append(time.perf_counter() - start)
                evaluations = fit.evaluations
            print(f'{positions:>5} {model:>9} {np.median(bare) * 1e3:>10.2f} '
                  f'{np.median(full) * 1e3:>10.2f} {evaluations:>12d}')


def bench_attitude(rate, seconds):
    """Print latency and CPU of the attitude node at ``rate`` Hz input."""
    from graph_harness.graph import Graph
    from accelcal_ros.rosutil.stamps import stamp_to_seconds
    from geometry_msgs.msg import Vector3Stamped
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Imu

    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    if 'ROS_DOMAIN_ID' not in os.environ:
        os.environ['ROS_DOMAIN_ID'] = str(random.randint(150, 199))
    log_dir = tempfile.mkdtemp(prefix='bench_calibration_')
    graph = Graph(log_dir=log_dir, name='bench_probe')
    try:
        qos = QoSProfile(depth=5000, reliability=ReliabilityPolicy.BEST_EFFORT,
                         history=HistoryPolicy.KEEP_LAST)
        raw = graph.collect(Imu, 'imu/data_raw', qos)
        att = graph.collect(Vector3Stamped, 'attitude', qos)
        graph.start('imu_driver', {'backend': 'sim', 'rate_hz': float(rate)})
        proc = graph.start('attitude')
        att.wait_for(int(rate), timeout=30.0)
        time.sleep(1.0)
        raw.clear()
        att.clear()
        cpu0, wall0 = cpu_seconds(proc.proc.pid), time.monotonic()
        time.sleep(seconds)
        raw_msgs, raw_rx = raw.snapshot()
        att_msgs, att_rx = att.snapshot()
        cpu = (cpu_seconds(proc.proc.pid) - cpu0) / (time.monotonic() - wall0)
    finally:
        graph.close()
        shutil.rmtree(log_dir, ignore_errors=True)
    raw_time = {round(stamp_to_seconds(m.header.stamp), 6): r for m, r in zip(raw_msgs, raw_rx)}
    hop, end_to_end = [], []
    for msg, received in zip(att_msgs, att_rx):
        stamp = stamp_to_seconds(msg.header.stamp)
        end_to_end.append(received - stamp)
        if round(stamp, 6) in raw_time:
            hop.append(received - raw_time[round(stamp, 6)])
    hop, end_to_end = np.array(hop) * 1e3, np.array(end_to_end) * 1e3
    # Samples the driver stamped between the first and the last attitude message received
    # (the sim driver stamps every 1/rate s), against the distinct ones that came back.
    stamps = np.unique(np.round(np.array([stamp_to_seconds(m.header.stamp)
                                          for m in att_msgs]) * rate).astype(np.int64))
    expected = stamps[-1] - stamps[0] + 1 if len(stamps) else 0
    print(f'attitude node at {rate:g} Hz input ({seconds:g} s, {os.cpu_count()} CPUs on this '
          'machine):')
    print(f'  attitude messages: {len(stamps)} of the {expected} samples stamped between '
          f'the first and the last received ({len(stamps) / max(expected, 1) * 100:.1f} %)')
    print(f'  added latency (attitude rx - imu/data_raw rx, same stamp): median '
          f'{np.median(hop):.2f} ms, p99 {np.percentile(hop, 99):.2f} ms')
    print(f'  end-to-end latency (attitude rx - sample stamp): median '
          f'{np.median(end_to_end):.2f} ms, p99 {np.percentile(end_to_end, 99):.2f} ms')
    print(f'  attitude node CPU: {cpu * 100:.0f} % of one core '
          f'({cpu / rate * 1e6:.0f} us per sample)')


def main():
    """Run the benchmarks."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--seconds', type=float, default=5.0)
    parser.add_argument('--rate', type=float, default=800.0)
    parser.add_argument('--repeat', type=int, default=20)
    parser.add_argument('--no-graph', action='store_true', help='fit times only')
    args = parser.parse_args()
    try:
        bench_fit(args.repeat)
        if not args.no_graph:
            bench_attitude(args.rate, args.seconds)
    except KeyboardInterrupt:
        print('interrupted', file=sys.stderr)
        return 130
    return 0


if __name__ == '__main__':
    sys.exit(main())
