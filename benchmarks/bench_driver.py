"""
Benchmark the ``imu_driver`` node (sim backend) in a real ROS 2 graph.

For each output data rate it starts the installed executable as its own process,
subscribes like ``ros2 topic echo`` (best effort, deep queue so the probe is not the
bottleneck), and prints achieved rate, samples lost (from the gaps in the evenly spaced
stamps), sample-to-subscriber latency (receive time - header stamp; median, p99) and the
driver's CPU use. Run after ``source tools/env.sh``::

    python benchmarks/bench_driver.py [--seconds 5] [--rates 100 400 800 3200]

``--callbacks N`` instead times the per-sample work of the high-rate nodes in one
process (no DDS delivery, no executor): ``attitude``'s and ``calibration``'s
``imu/data_raw`` callbacks (a running session) and the driver's publishing of a sim
batch, in microseconds per sample over N samples; ``--profile`` adds cProfile's top
entries for each::

    python benchmarks/bench_driver.py --callbacks 20000 [--profile]
"""
import argparse
import os
import shutil
import sys
import tempfile
import time

from graph_harness.graph import Graph
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


def _imu_messages(count):
    """Return ``count`` Imu messages of the simulated sensor at 800 Hz (dwells and moves)."""
    from accelcal_ros.driver.sim_sensor import SimulatedAdxl345
    from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2

    sim = SimulatedAdxl345(rate_hz=800.0, dwell_s=2.0, move_s=1.0)
    t = np.arange(count) / 800.0
    accel = (sim.read(t) * STANDARD_GRAVITY_M_S2).tolist()
    messages = []
    for ti, (x, y, z) in zip(t.tolist(), accel):
        msg = Imu()
        msg.header.frame_id = 'imu_link'
        msg.header.stamp.sec, msg.header.stamp.nanosec = int(ti), int(ti % 1 * 1e9)
        msg.linear_acceleration.x, msg.linear_acceleration.y = x, y
        msg.linear_acceleration.z = z
        messages.append(msg)
    return messages


def _time_calls(label, call, items, profile):
    """Print the cost of ``call(item)`` per item (and cProfile's top entries)."""
    import cProfile
    import pstats

    start = time.perf_counter()
    for item in items:
        call(item)
    per_us = (time.perf_counter() - start) / len(items) * 1e6
    print(f'{label:<44} {per_us:8.1f} us/sample', flush=True)
    if profile:
        profiler = cProfile.Profile()
        profiler.enable()
        for item in items:
            call(item)
        profiler.disable()
        pstats.Stats(profiler).sort_stats('tottime').print_stats(8)


def callbacks(count, profile):
    """Time the per-sample callbacks of attitude, calibration and the driver in-process."""
    import rclpy
    from accelcal_ros.attitude.node import AttitudeNode
    from accelcal_ros.calibration.node import CalibrationNode
    from accelcal_ros.driver.node import ImuDriverNode
    from accelcal_ros.driver.sources import Batch

    rclpy.init(args=['--ros-args', '-p', 'imu_driver:backend:=sim', '-p',
                     'imu_driver:rate_hz:=800.0'])
    messages = _imu_messages(count)
    attitude = AttitudeNode()
    _time_calls('attitude: imu/data_raw callback', attitude._on_imu, messages, profile)
    calibration = CalibrationNode()
    calibration.calibrator.start()
    _time_calls('calibration: imu/data_raw callback (session)', calibration._on_imu,
                messages, profile)
    driver = ImuDriverNode()
    driver.close()
    sim = driver.source.sensor
    batch_size = 4
    t = np.arange(count) / sim.rate_hz
    samples, roll, pitch = sim.read_with_truth(t)
    batches = [Batch(t[k:k + batch_size], samples[k:k + batch_size],
                     np.stack([roll[k:k + batch_size], pitch[k:k + batch_size]], axis=1))
               for k in range(0, count, batch_size)]
    start = time.perf_counter()
    for batch in batches:
        driver._publish(batch)
    per_us = (time.perf_counter() - start) / count * 1e6
    print(f'{"imu_driver: publishing (sim, batches of 4)":<44} {per_us:8.1f} us/sample')
    for node in (attitude, calibration, driver):
        node.destroy_node()
    rclpy.shutdown()


def main():
    """Run the benchmark and print a table."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--seconds', type=float, default=5.0)
    parser.add_argument('--rates', type=float, nargs='+', default=[100, 400, 800, 3200])
    parser.add_argument('--callbacks', type=int, default=0,
                        help='time the per-sample callbacks in-process over N samples')
    parser.add_argument('--profile', action='store_true', help='with --callbacks: cProfile')
    args = parser.parse_args()
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    if args.callbacks:
        callbacks(args.callbacks, args.profile)
        return
    log_dir = tempfile.mkdtemp(prefix='bench_driver_')
    print(f'imu_driver sim backend, {args.seconds:g} s per rate, {os.cpu_count()} CPU cores')
    print(f'{"rate Hz":>8} {"achieved":>9} {"ratio":>6} {"received":>9} {"lost":>5} '
          f'{"lat med ms":>10} {"lat p99 ms":>10} {"driver CPU":>10}')
    try:
        for rate in args.rates:
            r = measure(rate, args.seconds, log_dir)
            print(f'{r["rate"]:8g} {r["achieved"]:9.1f} {r["achieved"] / rate:6.3f} '
                  f'{r["received"]:9d} {r["lost"]:5d} {r["lat_med"]:10.2f} '
                  f'{r["lat_p99"]:10.2f} {100 * r["cpu"]:9.0f}%', flush=True)
    except KeyboardInterrupt:
        print('interrupted', file=sys.stderr)
        return 130
    finally:
        shutil.rmtree(log_dir, ignore_errors=True)


if __name__ == '__main__':
    sys.exit(main())
