"""
Roll/pitch error of the ``attitude`` node after a field calibration: per message and per dwell.

The demo's flow with processes in a ROS graph: ``imu_driver`` (sim backend, paper A's
K = 500 sensor as truth, datasheet noise, 14 recommended orientations visited in turn),
``calibration`` (a session started, the captures automatic, finished: the fitted file is
set on ``attitude``) and ``attitude``. Then ``attitude`` is compared with the simulator's
truth (``sim/attitude_truth``, same stamps) over the still dwells: the error of every
single message (roll and pitch errors pooled, absolute) and the mean error per dwell (what
an averaged reading gives). Run after ``source tools/env.sh``::

    python benchmarks/bench_attitude_error.py [--seconds 20] [--rate 100]
"""
import argparse
import os
import random
import shutil
import sys
import tempfile
import time

from accelcal_ros.calibration.coverage import recommended_directions, roll_pitch_deg_of
from accelcal_ros.driver.sim_truth import dwell_errors_deg
from accelcal_ros.rosutil.stamps import stamp_to_seconds
import numpy as np


def per_message_errors_deg(attitude_msgs, truth_msgs, margin=20):
    """Return |roll error| and |pitch error| (deg) of every message inside a still dwell."""
    truth = sorted((stamp_to_seconds(m.header.stamp), m.vector.x, m.vector.y)
                   for m in truth_msgs)
    by_stamp = {round(t, 6): k for k, (t, _, _) in enumerate(truth)}
    errors = []
    for msg in attitude_msgs:
        k = by_stamp.get(round(stamp_to_seconds(msg.header.stamp), 6))
        if k is None or k < margin or k + margin >= len(truth):
            continue
        _, roll, pitch = truth[k]
        if any(abs(truth[j][1] - roll) > 1e-9 or abs(truth[j][2] - pitch) > 1e-9
               for j in (k - margin, k + margin)) or abs(pitch) > np.radians(80.0):
            continue
        errors += [abs(np.angle(np.exp(1j * (msg.vector.x - roll)))), abs(msg.vector.y - pitch)]
    return np.degrees(np.array(errors))


def run(seconds, rate):
    """Calibrate in a graph, then return (per-message errors, per-dwell mean errors) in deg."""
    from diagnostic_msgs.msg import DiagnosticStatus
    from geometry_msgs.msg import Vector3Stamped
    from graph_harness.graph import Graph
    from std_srvs.srv import Trigger

    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    if 'ROS_DOMAIN_ID' not in os.environ:
        os.environ['ROS_DOMAIN_ID'] = str(random.randint(150, 199))
    log_dir = tempfile.mkdtemp(prefix='bench_attitude_error_')
    graph = Graph(log_dir=log_dir, name='bench_probe')
    try:
        poses = roll_pitch_deg_of(recommended_directions(14)).ravel().tolist()
        graph.start('imu_driver', {'backend': 'sim', 'rate_hz': float(rate), 'seed': 2,
                                   'sim.poses_deg': poses, 'sim.dwell_s': 1.5,
                                   'sim.move_s': 0.4})
        graph.start('calibration', {'output_file': os.path.join(log_dir, 'calibration.yaml'),
                                    'min_still_s': 0.7})
        graph.start('attitude')
        status = graph.collect(DiagnosticStatus, 'calibration/status', 10)
        if not graph.call(Trigger, 'calibration/start', timeout=60.0).success:
            raise RuntimeError('calibration/start refused')
        deadline, captures = time.monotonic() + 90.0, 0
        while time.monotonic() < deadline and captures < 14:
            time.sleep(0.5)
            messages = status.snapshot()[0]
            if messages:
                captures = int({kv.key: kv.value for kv in messages[-1].values}['captures'])
        reply = graph.call(Trigger, 'calibration/finish', timeout=60.0)
        if not reply.success:
            raise RuntimeError(f'calibration/finish: {reply.message}')
        time.sleep(2.0)   # the attitude node has the new calibration
        attitude = graph.collect(Vector3Stamped, 'attitude')
        truth = graph.collect(Vector3Stamped, 'sim/attitude_truth')
        time.sleep(seconds)
        att_msgs, truth_msgs = attitude.snapshot()[0], truth.snapshot()[0]
    finally:
        graph.close()
        shutil.rmtree(log_dir, ignore_errors=True)
    dwell = dwell_errors_deg(att_msgs, truth_msgs)
    return (per_message_errors_deg(att_msgs, truth_msgs),
            np.abs(np.array(list(dwell.values()))).ravel())


def main():
    """Print the per-message and per-dwell error table."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--seconds', type=float, default=20.0)
    parser.add_argument('--rate', type=float, default=100.0)
    args = parser.parse_args()
    try:
        single, dwell = run(args.seconds, args.rate)
    except KeyboardInterrupt:
        print('interrupted', file=sys.stderr)
        return 130
    print(f'attitude after a field calibration, sim ADXL345 at {args.rate:g} Hz, '
          f'{args.seconds:g} s of dwells (roll and pitch errors pooled, absolute, deg)')
    print(f'{"":28s}{"count":>7s}{"median":>9s}{"p90":>9s}{"p99":>9s}{"max":>9s}')
    for label, values in (('single messages', single), ('dwell means (averaged)', dwell)):
        if not len(values):
            print(f'{label:28s}{0:7d}')
            continue
        print(f'{label:28s}{len(values):7d}{np.median(values):9.3f}'
              f'{np.percentile(values, 90):9.3f}{np.percentile(values, 99):9.3f}'
              f'{values.max():9.3f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
