"""
Stress the ``lidar_calibration`` node: positions captured while its process is starved.

Starts the installed node as its own process, then drives the graph test's protocol (five
rest positions, IMU 50 Hz best effort, scans as 20 reliable packets per revolution, 20 per
capture) while the node is either starved of CPU (``--hogs N`` busy processes, node at
nice 19) or frozen (``--stop-s S``: SIGSTOP for S seconds over the second position's
scans). Prints, per trial, the positions captured one second after the driving ended (the
node catches up on its queued backlog) and the boresight error. Node parameters can be
overridden, e.g. ``--param queue_depth=5 --param imu_queue_depth=200`` for the depths
before they became parameters. Run after ``source tools/env.sh``::

    python benchmarks/stress_lidar_capture.py [--trials 3] [--hogs 3] [--stop-s 0]
"""
import argparse
import os
import signal
import subprocess
import tempfile
import threading
import time

from graph_harness.domain import allocate_domain_id

if 'ROS_DOMAIN_ID' not in os.environ:
    _LEASE = allocate_domain_id()
    os.environ['ROS_DOMAIN_ID'] = str(_LEASE.domain_id)
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from accelcal_ros.lidar import scanner_sim as sim  # noqa: E402, I100 (after the domain is chosen)
from accelcal_ros.lidar.boresight import load_boresight  # noqa: E402
from accelcal_ros.lidar.scanner_sim_ros import (  # noqa: E402
    drive_static_positions, PACKETS_PER_REVOLUTION)
from accelcal_ros.lidar.wahba import rotation_angle_deg  # noqa: E402
from graph_harness.graph import Graph  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402
import yaml  # noqa: E402

PICKS = [1, 2, 5, 7, 12]


def trial(args, log_dir):
    """Run one trial; return ``(positions captured, boresight error deg or None)``."""
    truth = sim.default_boresight()
    protocol = sim.simulate_protocol(truth, seed=11)
    out = os.path.join(log_dir, 'bs.yaml')
    params = {'output_file': out, 'prior_rpy_deg': [0.0, 45.0, 0.0], 'min_static_s': 0.5,
              'min_positions': 2, 'points_reliable': True,
              'clouds_per_capture': PACKETS_PER_REVOLUTION}
    params.update({k: yaml.safe_load(v) for k, v in (p.split('=', 1) for p in args.param)})
    graph = Graph(log_dir=log_dir, name='stress_probe')
    hogs = []
    try:
        proc = graph.start('lidar_calibration', params=params)
        graph.call(Trigger, 'lidar_calibration/start', timeout=20.0)  # the node is up
        pid = proc.proc.pid
        if args.hogs:
            os.setpriority(os.PRIO_PROCESS, pid, 19)
            hogs = [subprocess.Popen(['yes'], stdout=subprocess.DEVNULL)
                    for _ in range(args.hogs)]
        if args.stop_s:
            def freeze():
                time.sleep(3.8)   # the second position rests from 3.4 s, scans 4.0-4.8 s
                os.kill(pid, signal.SIGSTOP)
                time.sleep(args.stop_s)
                os.kill(pid, signal.SIGCONT)
            threading.Thread(target=freeze, daemon=True).start()
        drive_static_positions(graph.node, protocol, PICKS, move_s=0.5, still_s=2.4, imu_hz=50.0)
        for hog in hogs:
            hog.kill()
        time.sleep(args.stop_s + 1.0)
        response = graph.call(Trigger, 'lidar_calibration/finish', timeout=30.0)
        captured = proc.output().count('captured pos')
        error = (rotation_angle_deg(load_boresight(out), truth) if response.success
                 else None)
        return captured, error
    finally:
        for hog in hogs:
            hog.kill()
        graph.close()


def main():
    """Parse arguments, run the trials, print one line each and a summary."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--trials', type=int, default=3)
    parser.add_argument('--hogs', type=int, default=3, help='busy processes (0 = none)')
    parser.add_argument('--stop-s', type=float, default=0.0, help='SIGSTOP the node this long')
    parser.add_argument('--param', action='append', default=[], metavar='NAME=VALUE',
                        help='node parameter override (YAML value)')
    args = parser.parse_args()
    print(f'{len(PICKS)} positions driven; hogs {args.hogs} (node at nice 19), '
          f'SIGSTOP {args.stop_s} s; overrides {args.param or "none"}')
    counts = []
    for k in range(args.trials):
        with tempfile.TemporaryDirectory() as log_dir:
            captured, error = trial(args, log_dir)
        counts.append(captured)
        err = 'n/a' if error is None else f'{error:.4f} deg'
        print(f'trial {k + 1}: {captured} of {len(PICKS)} positions captured, '
              f'boresight error {err}')
    print(f'captured per trial: {counts}; mean {sum(counts) / len(counts):.1f} of {len(PICKS)}')


if __name__ == '__main__':
    main()
