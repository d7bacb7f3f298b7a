"""
Benchmark the ``imu_driver`` node (sim backend) in a real ROS 2 graph.

For each output data rate it starts the installed executable as its own process,
subscribes like ``ros2 topic echo`` (best effort, deep queue so the probe is not the
bottleneck), and prints achieved rate, samples lost (from the gaps in the evenly spaced
stamps), sample-to-subscriber latency (receive time - header stamp; median, p99) and the
driver's CPU use. Run after ``source tools/env.sh``::

    python benchmarks/bench_driver.py [--seconds 5] [--rates 100 400 800 3200]
"""
import argparse
import os
import time

from accelcal_ros.demo.graph import Graph
import numpy as np
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu


def cpu_seconds(pid):
    """Return user + system CPU seconds of a process (from /proc)."""
    with open(f'/proc/{pid}/stat') as handle:
        fields = handle.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def measure(rate, seconds, log_dir):
    """Return a dict of figures for one rate."""
    graph = Graph(log_dir=log_dir, name='bench_probe')
    try:
        qos = QoSProfile(depth=5000, reliability=ReliabilityPolicy.BEST_EFFORT,
                         history=HistoryPolicy.KEEP_LAST)
        imu = graph.collect(Imu, 'imu/data_raw', qos)
        proc = graph.start('imu_driver', {'backend': 'sim', 'rate_hz': float(rate)})
        imu.wait_for(int(rate), timeout=30.0)  # discovery done, warm
        time.sleep(1.0)
        imu.clear()
        cpu0, wall0 = cpu_seconds(proc.proc.pid), time.monotonic()
        time.sleep(seconds)
        msgs, received = imu.snapshot()
        cpu = (cpu_seconds(proc.proc.pid) - cpu0) / (time.monotonic() - wall0)
    finally:
        graph.close()
    stamps = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in msgs])
    latency = (np.array(received) - stamps) * 1e3
    unique = np.unique(np.round(stamps * rate).astype(np.int64))
    expected = unique[-1] - unique[0] + 1
    span = unique[-1] - unique[0]
    return {'rate': rate, 'achieved': (len(unique) - 1) * rate / span if span else 0.0,
            'received': len(unique), 'lost': int(expected - len(unique)),
            'lat_med': float(np.median(latency)),
            'lat_p99': float(np.percentile(latency, 99)), 'cpu': cpu}


def main():
    """Run the benchmark and print a table."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--seconds', type=float, default=5.0)
    parser.add_argument('--rates', type=float, nargs='+', default=[100, 400, 800, 3200])
    args = parser.parse_args()
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    log_dir = '/tmp/bench_driver'
    os.makedirs(log_dir, exist_ok=True)
    print(f'imu_driver sim backend, {args.seconds:g} s per rate, {os.cpu_count()} CPU cores')
    print(f'{"rate Hz":>8} {"achieved":>9} {"ratio":>6} {"received":>9} {"lost":>5} '
          f'{"lat med ms":>10} {"lat p99 ms":>10} {"driver CPU":>10}')
    for rate in args.rates:
        r = measure(rate, args.seconds, log_dir)
        print(f'{r["rate"]:8g} {r["achieved"]:9.1f} {r["achieved"] / rate:6.3f} '
              f'{r["received"]:9d} {r["lost"]:5d} {r["lat_med"]:10.2f} {r["lat_p99"]:10.2f} '
              f'{100 * r["cpu"]:9.0f}%', flush=True)


if __name__ == '__main__':
    main()
