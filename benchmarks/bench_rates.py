"""
CPU per sample and samples delivered through ``attitude`` and ``calibration`` at the ADXL345 rates.

For each rate (default 100, 400, 800, 1600, 3200 Hz) the installed ``imu_driver`` (sim
backend) runs as its own process and, one after the other, these consumers run beside it
as their own processes (issue 15, part 1):

* ``passthrough``: the bare rclpy floor (``benchmarks/passthrough_node.py``, rclpy's default
  executor: ``rclpy.spin``);
* ``attitude`` and ``calibration`` (a session started, so every sample goes through the
  still detector) and ``attitude_gyro`` (the attitude node's gyro-aided path: each
  sample is given an angular velocity, 0.01 rad/s on each axis with its covariance,
  inside the measured process before the node's callback), ``attitude_gyro_arm`` (the
  same with ``lever_arm_m`` [1.0, 0.3, 0.8]: the rotation's acceleration at the sensor
  computed per sample) on each executor of :func:`accelcal_ros.rosutil.runner.run`:
  events, single, multi (``ACCELCAL_EXECUTOR``).

Each consumer process is the node class run as its executable runs it, with its sample
callback wrapped by a counter that publishes ``[count, first stamp, last stamp]`` twice
a second on ``bench/counts`` (no high-rate probe subscriber competing for the CPU).
Delivered = samples the node received / samples the driver stamped in the same span
(the sim driver stamps every sample 1/rate apart). CPU per sample = the consumer's
user + system time (``/proc/<pid>/stat``) over the window / the samples it received in
the window (rate x window x delivered); the driver's is printed beside it. Run after
``source tools/env.sh``::

    python benchmarks/bench_rates.py [--seconds 10] [--rates 800 3200] \
        [--consumers passthrough attitude attitude_gyro attitude_gyro_arm calibration] \
        [--executors events single multi]

Numbers from a loaded machine are indicative only; take final figures on a quiet one.
"""
import argparse
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time

COUNTS_TOPIC = 'bench/counts'
EXECUTORS = ('events', 'single', 'multi')


# -- child: one consumer process ----------------------------------------------------------
def _counted(node_class, inject_gyro=False):
    """Subclass ``node_class`` so that every ``imu/data_raw`` sample is counted."""
    from std_msgs.msg import Float64MultiArray

    class Counted(node_class):
        def __init__(self):
            self._bench = [0, 0.0, 0.0]
            super().__init__()
            self._bench_pub = self.create_publisher(Float64MultiArray, COUNTS_TOPIC, 10)
            self.create_timer(0.5, self._bench_publish)

        def _on_imu(self, msg):
            counts = self._bench
            stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
            if counts[0] == 0:
                counts[1] = stamp
            counts[0] += 1
            counts[2] = stamp
            if inject_gyro:
                w = msg.angular_velocity
                w.x = w.y = w.z = 0.01
                msg.angular_velocity_covariance[0] = 1e-4
            super()._on_imu(msg)

        def _bench_publish(self):
            self._bench_pub.publish(Float64MultiArray(data=[float(v) for v in self._bench]))

    return Counted


def serve(consumer):
    """Run one consumer node until SIGINT/SIGTERM (child process)."""
    if consumer == 'passthrough':
        sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
        from passthrough_node import PassThroughNode
        import rclpy
        from rclpy.executors import ExternalShutdownException

        rclpy.init()
        node = _counted(PassThroughNode)()
        try:
            rclpy.spin(node)
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        return 0
    from accelcal_ros.rosutil.runner import run
    args = [sys.argv[0]]
    if consumer in ('attitude', 'attitude_gyro', 'attitude_gyro_arm'):
        from accelcal_ros.attitude.node import AttitudeNode as node_class
        if consumer == 'attitude_gyro_arm':
            args += ['--ros-args', '-p', 'lever_arm_m:=[1.0, 0.3, 0.8]']
    else:
        from accelcal_ros.calibration.node import CalibrationNode as node_class
    return run(_counted(node_class, consumer.startswith('attitude_gyro')), args=args,
               executor='events')


# -- parent: the measurement ----------------------------------------------------------------
def cpu_seconds(pid):
    """Return user + system CPU seconds of a process (from /proc)."""
    with open(f'/proc/{pid}/stat') as handle:
        fields = handle.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


class Probe:
    """rclpy node in its own context and thread: latest counts, service calls."""

    def __init__(self):
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from std_msgs.msg import Float64MultiArray

        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('bench_rates_probe', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.latest = None
        self._clients = {}
        self.node.create_subscription(Float64MultiArray, COUNTS_TOPIC, self._on_counts, 10)
        self._stop = False
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self):
        while not self._stop and self.context.ok():
            self.executor.spin_once(timeout_sec=0.05)

    def _on_counts(self, msg):
        self.latest = (time.monotonic(), list(msg.data))

    def fresh_counts(self, after, timeout=10.0):
        """Return the first counts received after monotonic time ``after``."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            latest = self.latest
            if latest is not None and latest[0] > after and latest[1][0] > 0:
                return latest[1]
            time.sleep(0.02)
        raise TimeoutError('the consumer reported no samples (is the driver publishing?)')

    def trigger(self, service, timeout=10.0):
        """Call a std_srvs/Trigger service; returns the response."""
        from std_srvs.srv import Trigger

        # One client per service for the probe's life: destroying one here, while the spin
        # thread may be waiting on it, races rclpy's wait set; destroy_node() in close(),
        # after that thread has ended, frees them.
        client = self._clients.get(service)
        if client is None:
            client = self._clients[service] = self.node.create_client(Trigger, service)
        if not client.wait_for_service(timeout_sec=timeout):
            raise TimeoutError(f'{service} did not appear')
        future = client.call_async(Trigger.Request())
        deadline = time.monotonic() + timeout
        while not future.done() and time.monotonic() < deadline:
            time.sleep(0.01)
        return future.result()

    def close(self):
        """Stop the probe."""
        import rclpy

        self._stop = True
        self._thread.join(timeout=2.0)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def _stop(proc):
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=10.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def measure(probe, rate, consumer, executor, seconds, warmup_s, log_dir):
    """Return a dict of figures for one consumer at one rate."""
    driver_exe = shutil.which('imu_driver')
    if driver_exe is None:
        raise SystemExit('imu_driver not found: source tools/env.sh first')
    tag = f'{consumer}_{executor}_{rate:g}'
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    env.pop('ACCELCAL_EXECUTOR', None)
    logs = [open(os.path.join(log_dir, f'{tag}_{name}.log'), 'w')
            for name in ('driver', 'consumer')]
    driver = subprocess.Popen(
        [driver_exe, '--ros-args', '-p', 'backend:=sim', '-p', f'rate_hz:={float(rate)}'],
        stdout=logs[0], stderr=subprocess.STDOUT, env=env)
    if executor != 'default':
        env['ACCELCAL_EXECUTOR'] = executor
    child = subprocess.Popen([sys.executable, os.path.abspath(__file__), '--serve', consumer],
                             stdout=logs[1], stderr=subprocess.STDOUT, env=env)
    try:
        probe.latest = None
        if consumer == 'calibration':
            response = probe.trigger('calibration/start', timeout=30.0)
            if response is None or not response.success:
                raise RuntimeError(f'calibration/start failed: {response}')
        probe.fresh_counts(0.0, timeout=30.0)
        time.sleep(warmup_s)
        counts0 = probe.fresh_counts(time.monotonic())
        wall0 = time.monotonic()
        cpu0, dcpu0 = cpu_seconds(child.pid), cpu_seconds(driver.pid)
        time.sleep(seconds)
        counts1 = probe.fresh_counts(time.monotonic())
        wall1 = time.monotonic()
        cpu1, dcpu1 = cpu_seconds(child.pid), cpu_seconds(driver.pid)
    finally:
        _stop(child)
        _stop(driver)
        for handle in logs:
            handle.close()
    expected = round((counts1[2] - counts0[2]) * rate)
    offered = (wall1 - wall0) * rate
    delivered = (counts1[0] - counts0[0]) / max(expected, 1)
    return {'rate': rate, 'consumer': consumer, 'executor': executor,
            'delivered': delivered,
            'cpu_us': (cpu1 - cpu0) / max(offered * delivered, 1.0) * 1e6,
            'cpu_percent': (cpu1 - cpu0) / (wall1 - wall0) * 100.0,
            'driver_us': (dcpu1 - dcpu0) / offered * 1e6}


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def _domain_id():
    try:
        from graph_harness.domain import allocate_domain_id
    except ImportError:
        return random.randint(60, 100)
    return allocate_domain_id().domain_id


def main(argv=None):
    """Parse options, run every case, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rates', type=float, nargs='+',
                        default=[100.0, 400.0, 800.0, 1600.0, 3200.0])
    consumers = ('passthrough', 'attitude', 'attitude_gyro', 'attitude_gyro_arm', 'calibration')
    parser.add_argument('--consumers', nargs='+', default=list(consumers), choices=consumers)
    parser.add_argument('--executors', nargs='+', default=list(EXECUTORS), choices=EXECUTORS)
    parser.add_argument('--seconds', type=float, default=10.0, help='measurement window')
    parser.add_argument('--warmup', type=float, default=2.0, help='seconds before it')
    parser.add_argument('--serve', help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve:
        return serve(args.serve)
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    os.environ['ROS_DOMAIN_ID'] = str(_domain_id())
    log_dir = tempfile.mkdtemp(prefix='bench_rates_')
    cases = [(c, e) for c in args.consumers
             for e in (['default'] if c == 'passthrough' else args.executors)]
    print(f'{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}; '
          f'{args.seconds:g} s per case')
    print(f'{"rate Hz":>8} {"consumer":>17} {"executor":>9} {"delivered %":>12} '
          f'{"CPU us/sample":>14} {"CPU %":>6} {"x floor":>8} {"driver us":>10}')
    probe = Probe()
    for sig in (signal.SIGINT, signal.SIGTERM):   # after rclpy.init, which takes them over
        signal.signal(sig, _interrupt)
    failed = True
    try:
        for rate in args.rates:
            floor = None
            for consumer, executor in cases:
                r = measure(probe, rate, consumer, executor, args.seconds, args.warmup,
                            log_dir)
                if consumer == 'passthrough':
                    floor = r['cpu_us']
                ratio = f'{r["cpu_us"] / floor:8.2f}' if floor else f'{"-":>8}'
                print(f'{rate:8g} {consumer:>17} {executor:>9} {r["delivered"] * 100:12.2f} '
                      f'{r["cpu_us"]:14.1f} {r["cpu_percent"]:6.1f} {ratio} '
                      f'{r["driver_us"]:10.1f}', flush=True)
        failed = False
    except KeyboardInterrupt:
        print('interrupted', file=sys.stderr)
        failed = False
        return 130
    finally:
        probe.close()
        if failed:
            print(f'node logs kept in {log_dir}', file=sys.stderr)
        else:
            shutil.rmtree(log_dir, ignore_errors=True)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
