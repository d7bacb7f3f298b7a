"""
Offline commands of the attitude feature.

* ``accelcal study motion [--rates 100 800] [--seeds N] [--drive-out drive.csv
  --odometry-out odo.csv]``:
  roll/pitch error through a simulated drive for accelerometer only, + odometry, + gyro,
  + both, beside the ``imufusion``/``ahrs`` anchors (:mod:`accelcal_ros.attitude.study`);
  optionally writes the drive as a recording (``t,ax,ay,az,gx,gy,gz``; s, m/s^2, rad/s)
  and its odometry (``t,v,yaw_rate``) for ``accelcal attitude``. Then the panorama's
  horizon error through the drive, measured on stitched frames (``--panorama-every``):
  the ``accelcal`` dispatcher's ``args.panorama_horizon`` renders and stitches them
  (:mod:`accelcal_ros.panorama.horizon_track`; features never import each other).

(``accelcal attitude REC`` itself is registered by the calibration feature's commands.)
"""
import sys
from typing import Any

from accelcal_ros.cli_args import float_in, int_in, nonnegative_int


def register(subparsers: Any, study_subparsers: Any) -> None:
    """Add this feature's subcommands to the ``accelcal`` parser."""
    p = study_subparsers.add_parser('motion', help='roll/pitch error through a simulated '
                                    'drive: accelerometer only, + odometry, + gyro, + both, '
                                    'and the imufusion/ahrs anchors')
    p.add_argument('--rates', type=float_in(10.0, 3200.0), nargs='+', default=[100.0],
                   help='sample rates in Hz (default 100)')
    p.add_argument('--seed', type=nonnegative_int, default=0, help='random seed (0)')
    p.add_argument('--no-anchors', action='store_true', help='skip imufusion and ahrs')
    p.add_argument('--vibration-g', type=float_in(0.0, 1.0), default=None, metavar='G',
                   help='road vibration of the drive (g rms on z, a third on x and y; '
                   'default 0.03; 0: a smooth floor, where a cruise looks still)')
    p.add_argument('--seeds', type=int_in(0, 100), default=0,
                   help="also the spread of the aided rows' p95 over seeds 0 .. N-1 "
                   '(at most 100)')
    p.add_argument('--drive-out', help="also write the (first rate's) drive as a CSV "
                   'recording t,ax,ay,az,gx,gy,gz (s, m/s^2, rad/s)')
    p.add_argument('--odometry-out', help='also write its odometry as CSV t,v,yaw_rate')
    p.add_argument('--panorama-every', type=nonnegative_int, default=10, metavar='N',
                   help='panorama horizon through the drive: stitch every N-th frame of a '
                   '25 fps video with each estimate (default 10; 0: skip)')
    p.set_defaults(handler=_study, file_outputs=frozenset({'drive_out', 'odometry_out'}))


def _study(args):
    from accelcal_ros.attitude import study

    status = 0
    for rate in args.rates:
        jitter = study.still_jitter(rate, seed=args.seed)
        print(f'Still rig at {rate:g} Hz, accelerometer only, defaults: horizon jitter between '
              f'25 fps frames {jitter["filter"]:.2f} px rms at f = {study.FOCAL_PX:g} px '
              f'(one raw sample per frame: {jitter["one sample"]:.2f} px; target <= 0.5: '
              f'{"meets" if jitter["filter"] <= 0.5 else "MISSES"})')
        rows = study.run_study(rate_hz=rate, seed=args.seed, anchors=not args.no_anchors,
                               vibration_g=_vibration(args))
        for line in study.format_rows(rows, rate, _vibration(args)):
            print(line)
        verdict = study.check_targets(rows)
        for line in verdict:
            print(line)
        if args.seeds > 1:
            for line in study.seed_spread(rate, args.seeds, _vibration(args)):
                print(line)
        if args.panorama_every:
            for line in _panorama_horizon(args, rate):
                print(line)
        print()
    if args.drive_out or args.odometry_out:
        _write_drive(args)
    return status


def _vibration(args) -> float:
    """Return the drive's road vibration (g): ``--vibration-g`` or the simulator's default."""
    from accelcal_ros.sensor.drive_sim import VIBRATION_G

    value = getattr(args, 'vibration_g', None)   # callers may build the namespace themselves
    return VIBRATION_G if value is None else float(value)


PANORAMA_AIDS = (('accel only', False, False), ('+ odometry', False, True),
                 ('+ gyro', True, False), ('+ gyro + odometry', True, True))
"""The package's estimators whose attitude the panorama horizon is measured with."""


def _panorama_horizon(args, rate):
    """Return the table of the drive's panorama horizon error per aid (stitched frames)."""
    from accelcal_ros.attitude import study
    from accelcal_ros.sensor.drive_sim import simulate_drive
    import numpy as np

    drive = simulate_drive(rate_hz=rate, seed=args.seed, vibration_g=_vibration(args))
    period = args.panorama_every / 25.0
    times = np.arange(study.SETTLE_S, drive.t[-1], period)
    index = np.searchsorted(drive.t, times, side='right') - 1   # the newest estimate
    truth = np.column_stack([drive.roll[index], drive.pitch[index]])
    estimates = {}
    for name, gyro, odometry in PANORAMA_AIDS:
        roll, pitch = study._package(drive, gyro, odometry)
        estimates[name] = np.column_stack([roll[index], pitch[index]])
    label = f' at {rate:g} Hz ({1.0 / period:g} fps)'
    return args.panorama_horizon(truth, estimates, label)['table']


def _write_drive(args):
    from accelcal_ros.fileio import write_text_atomic
    from accelcal_ros.sensor.drive_sim import simulate_drive
    from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
    import numpy as np

    drive = simulate_drive(rate_hz=args.rates[0], seed=args.seed, vibration_g=_vibration(args))
    if args.drive_out:
        table = np.column_stack([drive.t, drive.accel_g * STANDARD_GRAVITY_M_S2,
                                 drive.gyro_rad_s])
        lines = ['t,ax,ay,az,gx,gy,gz'] + [
            ','.join(f'{v:.6f}' if k == 0 else f'{v:.7g}' for k, v in enumerate(row))
            for row in table.tolist()]
        write_text_atomic(args.drive_out, '\n'.join(lines) + '\n')
        print(f'wrote {drive.t.size} samples to {args.drive_out} (lever arm '
              f'{list(drive.lever_arm_m)} m from the odometry reference point)')
    if args.odometry_out:
        lines = ['t,v,yaw_rate'] + [f'{t:.6f},{v:.5f},{r:.6f}' for t, v, r in zip(
            drive.odo_t.tolist(), drive.odo_speed.tolist(), drive.odo_yaw_rate.tolist())]
        write_text_atomic(args.odometry_out, '\n'.join(lines) + '\n')
        print(f'wrote {drive.odo_t.size} odometry rows to {args.odometry_out}')
    sys.stdout.flush()
