"""
Offline commands of the calibration feature (recordings ``t,ax,ay,az`` in s and m/s^2).

* ``accelcal calibrate rec.csv -o calib.yaml [--model full|diagonal]``: the node's static
  detection and LM fit on a recording;
* ``accelcal apply rec.csv --calibration calib.yaml -o corrected.csv``: calibrated samples
  in the same CSV format;
* ``accelcal attitude rec.csv --calibration calib.yaml [--odometry odo.csv]``: roll/pitch
  per sample (deg) from :func:`accelcal_ros.sensor.tilt_series.estimate_series` (adaptive
  averaging; gyro-aided when the recording has ``gx,gy,gz`` columns, rad/s, or its bag
  Imu carries angular velocity; odometry-aided with ``--odometry``);
* ``accelcal plot-calibration calib.yaml -o calib.png``: captured points against the unit
  sphere and the per-position residuals;
* ``accelcal study calibration``: the Monte Carlo accuracy study and paper A's worked
  example.
"""
import argparse
import sys
from typing import Any, Optional, Tuple, TYPE_CHECKING

from accelcal_ros.cli_args import float_in, int_in, nonnegative_int, positive_int
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2 as STANDARD_GRAVITY

if TYPE_CHECKING:  # (numpy: imported where a command runs)
    import numpy as np


def register(subparsers: Any, study_subparsers: Any) -> None:
    """Add this feature's subcommands to the ``accelcal`` parser."""
    p = subparsers.add_parser('calibrate', help='fit a calibration to a recording of still '
                              'positions (CSV t,ax,ay,az in s and m/s^2)')
    p.add_argument('recording', help='CSV recording (t,ax,ay,az; s, m/s^2) or bag (rosbag2 '
                   'directory, .mcap, .db3, ROS 1 .bag) with a sensor_msgs/Imu topic')
    _add_bag_arguments(p)
    p.add_argument('-o', '--output', required=True, help='calibration YAML to write')
    p.add_argument('--model', default='full', choices=('full', 'diagonal'),
                   help='full (scale, bias, misalignment; default) or diagonal (paper A)')
    p.add_argument('--min-separation-deg', type=float_in(0.0, 180.0, low_open=True),
                   default=20.0,
                   help='a still dwell is a new position if its direction is more than '
                        'this from every captured one (default 20)')
    p.add_argument('--still-threshold-g', type=float_in(0.0, 16.0, low_open=True), default=0.01,
                   help='moving-std threshold of the still detector in g (default 0.01)')
    p.add_argument('--min-still-s', type=float_in(0.0, 3600.0, low_open=True), default=1.0,
                   help='minimum still time of a position in s (default 1.0)')
    p.add_argument('--window-s', type=float_in(0.0, 600.0, low_open=True), default=0.3,
                   help='moving-variance window in s (default 0.3)')
    p.add_argument('--plot', help='also write the calibration plot (PNG) here')
    p.set_defaults(handler=_calibrate, file_outputs=frozenset({'output'}),
                   output_suffixes={'output': ('.yaml', '.yml')})

    p = subparsers.add_parser('apply', help='write calibrated samples of a recording')
    p.add_argument('recording', help='CSV recording (t,ax,ay,az; s, m/s^2) or bag (rosbag2 '
                   'directory, .mcap, .db3, ROS 1 .bag) with a sensor_msgs/Imu topic')
    _add_bag_arguments(p)
    p.add_argument('--calibration', required=True, help='calibration YAML')
    p.add_argument('-o', '--output', required=True, help='CSV to write (same format)')
    p.set_defaults(handler=_apply)

    p = subparsers.add_parser('attitude', help='print roll/pitch of a recording')
    p.add_argument('recording', help='CSV recording (t,ax,ay,az[,gx,gy,gz]; s, m/s^2, rad/s) '
                   'or bag (rosbag2 directory, .mcap, .db3, ROS 1 .bag) with a '
                   'sensor_msgs/Imu topic (its angular velocity is used when provided)')
    _add_bag_arguments(p)
    p.add_argument('--calibration', help='calibration YAML (default: uncalibrated)')
    p.add_argument('--odometry', help='odometry CSV t,v,yaw_rate (s, m/s, rad/s): the '
                   "vehicle's acceleration is removed from the specific force")
    p.add_argument('--lever-arm', type=float_in(-100.0, 100.0), nargs=3, default=[0.0] * 3,
                   metavar=('X', 'Y', 'Z'), help="sensor position from the vehicle's reference "
                   "point (the odometry's, e.g. the rear axle centre), m, vehicle frame "
                   "(default 0 0 0: unknown); with a gyro, its rotation's acceleration there is "
                   'removed and turns leave pitch to the accelerometer')
    p.add_argument('--no-gyro', action='store_true', help='ignore angular velocity')
    p.add_argument('--platform-accel-g', type=float_in(0.0, 1.0), default=0.0,
                   help='steady acceleration the platform may have (g; default 0): '
                        'accelerometer only, the std columns include the tilt it could fake')
    p.add_argument('--still-time-constant-s', type=float_in(0.01, 60.0), default=2.0,
                   help='longest averaging while still (default 2 s)')
    p.add_argument('--moving-time-constant-s', type=float_in(0.001, 10.0), default=0.04,
                   help='low-pass while moving (default 0.04 s)')
    p.add_argument('--time-constant-s', type=float_in(0.0, 3600.0), default=0.0,
                   help='fixed low-pass time constant in s, accelerometer only, instead of '
                        'the adaptive filter (default 0: adaptive)')
    p.add_argument('--accel-threshold-g', type=float_in(0.0, 16.0, low_open=True), default=0.05,
                   help='flag samples whose |f| departs from 1 g by more (default 0.05)')
    p.add_argument('--every', type=positive_int, default=1, help='print every N-th sample')
    p.add_argument('-o', '--output', help='write CSV here instead of printing')
    p.set_defaults(handler=_attitude, file_outputs=frozenset({'output'}),
                   output_suffixes={'output': ('.csv',)})

    p = subparsers.add_parser('plot-calibration', help='plot a calibration file (PNG)')
    p.add_argument('calibration', help='calibration YAML written by calibrate/finish')
    p.add_argument('-o', '--output', required=True, help='PNG to write')
    p.set_defaults(handler=_plot, file_outputs=frozenset({'output'}))

    p = study_subparsers.add_parser('calibration', help='Monte Carlo accuracy of the field '
                                    'calibration vs number of positions; paper A example')
    p.add_argument('--trials', type=int_in(1, 10000), default=100,
                   help='calibrations per row (100; at most 10000)')
    p.add_argument('--seed', type=nonnegative_int, default=0, help='random seed (0)')
    p.add_argument('--quick', action='store_true', help='20 trials, K in 6, 12, 100')
    p.set_defaults(handler=_study)


def _add_bag_arguments(p):
    """Bag options of calibrate/apply/attitude (a CSV recording ignores none of them)."""
    from accelcal_ros.recording.cli_support import add_stamp_argument

    p.add_argument('--topic', help='bags: sensor_msgs/Imu topic (default: the only one)')
    add_stamp_argument(p)
    if p.prog.endswith(' apply'):
        p.add_argument('--corrected-topic', help='bag output: topic of the corrected Imu '
                       'messages (default: the input topic, replaced; another name keeps '
                       'the raw topic beside it)')
        p.add_argument('--format', choices=('mcap', 'sqlite3'), default='mcap',
                       help='bag output: rosbag2 storage (default mcap; a .bag output is '
                            'ROS 1)')


def _read_recording_of(args):
    """Return (t, accel in g) of a CSV recording or of a bag's Imu topic."""
    from accelcal_ros.recording.bag import is_bag
    from accelcal_ros.recording.cli_support import open_bag, warn

    if not is_bag(args.recording):
        t, accel_g, _ = _read_csv_recording(args)
        return t, accel_g
    from accelcal_ros.recording.streams import read_imu

    with open_bag(args.recording, args.stamp) as bag:
        imu = read_imu(bag, args.topic)
    warn(imu.warnings)
    print(f'{args.recording}: {imu.topic}, {len(imu.t)} samples over {imu.t[-1]:.1f} s; '
          f'times in s from its first sample at {imu.epoch_ns / 1e9:.6f} s', file=sys.stderr)
    return imu.t, imu.accel / STANDARD_GRAVITY


CsvRecording = Tuple['np.ndarray', 'np.ndarray', Optional['np.ndarray']]
"""``(t s, accel g, gyro rad/s or None)`` of a CSV recording."""


def _read_csv_recording(args: argparse.Namespace) -> CsvRecording:
    """
    Return ``(t s, accel g, gyro rad/s or None)`` of a command's CSV recording.

    :func:`accelcal_ros.sensor.recording.read_recording` with NaN samples kept (the
    calibration skips them); ``--topic`` is for bags only.
    """
    from accelcal_ros.sensor.recording import read_recording

    if args.topic:
        from accelcal_ros.errors import InputError
        raise InputError(f'--topic applies to bags; {args.recording} is a CSV recording')
    recording = read_recording(args.recording, finite=False)
    return recording.t, recording.accel / STANDARD_GRAVITY, recording.gyro


def _check_apply_options(args: argparse.Namespace) -> None:
    """
    Refuse an ``apply`` output its input cannot give, and a bad ``--corrected-topic``.

    A CSV recording is written as CSV (a bag-like ``-o`` would get CSV text under a bag's
    name); ``--corrected-topic`` names a topic of a bag output and must be a valid ROS
    topic name (a leading ``/`` is added). Checked before anything is read.
    """
    from accelcal_ros.errors import InputError
    from accelcal_ros.recording.bag import full_topic_name, is_bag
    from accelcal_ros.recording.cli_support import is_bag_output

    bag_output = is_bag_output(args.output)
    if bag_output and not is_bag(args.recording):
        raise InputError(f'-o {args.output}: {args.recording} is a CSV recording, written as '
                         'CSV: give -o NAME.csv (a bag output needs a bag input)')
    if args.corrected_topic is None:
        return
    if not bag_output:
        raise InputError(f'--corrected-topic applies to a bag output; -o {args.output} is a '
                         'CSV')
    if not args.corrected_topic:
        raise InputError('--corrected-topic is empty: give a topic name, or leave the option '
                         'out to replace the input topic')
    args.corrected_topic = full_topic_name(args.corrected_topic, '--corrected-topic')


def _writes_bag(args):
    from accelcal_ros.recording.bag import is_bag
    from accelcal_ros.recording.cli_support import is_bag_output

    return is_bag(args.recording) and is_bag_output(args.output)


def _apply_to_bag(args, model):
    """
    Copy every topic of the input bag, the Imu topic with calibrated linear_acceleration.

    The corrected messages keep header, covariances and receive times; the specific force
    is ``model.correct(a / g) * g`` (m/s^2). A ROS 1 bag is written as ROS 1 (``.bag``).
    """
    from accelcal_ros.errors import InputError
    from accelcal_ros.recording.cli_support import open_bag
    from accelcal_ros.recording.writer import BagWriter, format_for
    import numpy as np

    with open_bag(args.recording, args.stamp) as bag:
        topic = bag.select_topic(args.topic, ('sensor_msgs/Imu',))
        fmt = format_for(args.output,
                         None if str(args.output).lower().endswith('.bag') else args.format)
        if bag.is_ros1 != (fmt == 'ros1'):
            raise InputError(f'{args.recording} is a {"ROS 1" if bag.is_ros1 else "rosbag2"} '
                             'bag: write the same kind (-o NAME.bag for ROS 1, a directory for '
                             'rosbag2)')
        out_topic = args.corrected_topic or topic
        topics = bag.topics()
        if out_topic != topic and out_topic in topics:
            raise InputError(f'--corrected-topic {out_topic}: {args.recording} already has '
                             f'that topic ({topics[out_topic].msgtype}, '
                             f'{topics[out_topic].count} messages); the corrected {topic} '
                             'would be mixed into it: give a new name, or leave the option '
                             'out to replace the input topic')
        corrected = skipped = 0
        with BagWriter(args.output, fmt) as writer:
            for name in sorted(topics):
                conn = bag.connection_of(name)
                qos = getattr(conn.ext, 'offered_qos_profiles', ())
                if name != topic or out_topic != topic:
                    writer.add_topic(name, topics[name].msgtype, qos, source=conn)
            writer.add_topic(out_topic, 'sensor_msgs/Imu',
                             getattr(bag.connection_of(topic).ext, 'offered_qos_profiles', ()))
            for message in bag.messages(sorted(topics), decode=[topic]):
                if message.topic == topic:
                    acc = message.msg.linear_acceleration
                    raw = np.array([[acc.x, acc.y, acc.z]])
                    if _usable(raw / STANDARD_GRAVITY)[0]:  # else skipped and counted
                        fixed = model.correct(raw / STANDARD_GRAVITY)[0] * STANDARD_GRAVITY
                        acc.x, acc.y, acc.z = (float(v) for v in fixed)
                        writer.write(out_topic, message.receive_ns, message.msg)
                        corrected += 1
                    else:
                        skipped += 1
                    if out_topic == topic:
                        continue
                writer.write_raw(message.topic, message.receive_ns, message.raw)
            if not corrected:
                raise InputError(f'{args.recording}: no usable {topic} sample (all {skipped} '
                                 'have a NaN, infinite or impossible linear_acceleration); '
                                 'nothing written')
    print(f'wrote {args.output}: {corrected} calibrated {out_topic} messages beside '
          f'{len(topics) - (out_topic == topic)} copied topic(s){_skipped_note(skipped)}')
    return 0


def _skipped_note(skipped: int) -> str:
    """Return the summary's note on skipped impossible samples ('' when none)."""
    from accelcal_ros.sensor.tilt import MAX_FORCE_G

    return (f'; {skipped} sample(s) with a NaN, infinite or impossible (beyond '
            f'{MAX_FORCE_G:g} g) value skipped, not written' if skipped else '')


def _usable(accel_g):
    """Which raw readings (N, 3) g are finite and within ``tilt.MAX_FORCE_G`` per axis."""
    from accelcal_ros.sensor.tilt import MAX_FORCE_G
    import numpy as np

    with np.errstate(invalid='ignore'):
        return np.all(np.abs(accel_g) <= MAX_FORCE_G, axis=-1)


def _finite_samples(recording: str, t, accel_g):
    """
    Return ``(t, accel_g, skipped)`` without the samples with a NaN, infinite or absurd value.

    As ``calibrate`` rejects them: skipped and counted, never corrected into invented values
    (an infinity on one axis would spread to the others through the misalignment); no usable
    sample is an InputError.
    """
    from accelcal_ros.errors import InputError
    import numpy as np

    usable = _usable(accel_g)
    if not usable.any():
        raise InputError(f'{recording}: no usable sample (all {len(t)} have a NaN, infinite '
                         'or impossible value); nothing written')
    return t[usable], accel_g[usable], int(np.count_nonzero(~usable))


def _calibrate(args):
    from accelcal_ros.calibration.session import Calibrator, CalibratorConfig
    from accelcal_ros.errors import CalibrationError
    from accelcal_ros.outputs import check_output_path, PNG_SUFFIXES
    from accelcal_ros.sensor.calibration_file import save_calibration

    if args.plot:
        check_output_path(args.plot, '--plot', PNG_SUFFIXES)
    t, accel_g = _read_recording_of(args)
    config = CalibratorConfig(model=args.model, min_separation_deg=args.min_separation_deg,
                              still_threshold_g=args.still_threshold_g,
                              min_still_s=args.min_still_s, window_s=args.window_s)
    calibrator = Calibrator(config)
    calibrator.start()
    events = calibrator.add_samples(t, accel_g) + calibrator.flush()
    for event in events:
        if not event.startswith('position'):
            print(event)
    rejected = calibrator.detector.rejected
    if rejected:
        print(f'{rejected} samples rejected (NaN: {calibrator.detector.rejected_nan}, '
              f'saturated: {calibrator.detector.rejected_saturated})')
    print(calibrator.progress().text())
    try:
        result = calibrator.finish()
    except CalibrationError as exc:
        raise CalibrationError(f'{args.recording}: {exc}; record the sensor still in more '
                               'orientations and run accelcal calibrate again') from None
    for warning in result.warnings:
        print(f'warning: {warning}')
    save_calibration(args.output, result)
    print(result.summary())
    sm = result.sensor_model
    print(f'scale {sm.scale.round(5).tolist()} +- {result.scale_std.round(5).tolist()}')
    print(f'bias {sm.bias.round(5).tolist()} +- {result.bias_std.round(5).tolist()} g')
    if result.model == 'full':
        print(f'misalignment {sm.misalignment.round(6).tolist()} rad')
    print(f'wrote {args.output}')
    if args.plot:
        from accelcal_ros.calibration.plot import plot_calibration_file
        plot_calibration_file(args.plot, args.output)
        print(f'wrote {args.plot}')
    return 0


def _warn_if_calibration_misfits(model, t, accel_g):
    """Warn (stderr) when |g| after correction is far from 1 in the still periods."""
    from accelcal_ros.sensor.stillness import still_segments
    import numpy as np

    segments = still_segments(t, accel_g)
    if not segments:
        return
    fit = model.gravity_fit(np.array([s.accel_mean for s in segments]))
    if not fit.fits:
        print(f'warning: {fit.message()} (means of {len(segments)} still periods)',
              file=sys.stderr)


def _apply(args):
    from accelcal_ros.sensor.calibration_file import load_sensor_model
    from accelcal_ros.sensor.recording import save_recording

    _check_apply_options(args)
    model = load_sensor_model(args.calibration)
    if _writes_bag(args):
        return _apply_to_bag(args, model)
    t, accel_g = _read_recording_of(args)
    t, accel_g, skipped = _finite_samples(args.recording, t, accel_g)
    _warn_if_calibration_misfits(model, t, accel_g)
    save_recording(args.output, t, model.correct(accel_g) * STANDARD_GRAVITY)
    print(f'wrote {len(t)} calibrated samples to {args.output}{_skipped_note(skipped)}')
    return 0


def _attitude(args):
    import math

    from accelcal_ros.errors import InputError
    from accelcal_ros.fileio import write_text_atomic
    from accelcal_ros.sensor.calibration_file import load_calibration
    from accelcal_ros.sensor.model import SensorModel
    from accelcal_ros.sensor.tilt import MAX_FORCE_G, MIN_FORCE_G
    from accelcal_ros.sensor.tilt_filter import FilterSettings
    from accelcal_ros.sensor.tilt_series import (estimate_series, odometry_coverage,
                                                 read_odometry_csv)
    import numpy as np

    if args.every < 1:
        raise InputError('--every must be at least 1')
    if args.calibration:
        record = load_calibration(args.calibration)
        for note in record.notes:
            print(f'note: {args.calibration}: {note}', file=sys.stderr)
        model = record.sensor_model
        tilt_std = np.radians(record.predicted_tilt_error_deg / 1.96) \
            if np.isfinite(record.predicted_tilt_error_deg) else 0.0
    else:
        model, tilt_std = SensorModel.identity(), 0.0
        print('note: no --calibration given: uncalibrated readings', file=sys.stderr)
    odometry = read_odometry_csv(args.odometry) if args.odometry else None
    t, accel_g, gyro = _read_attitude_input(args)
    if args.no_gyro:
        gyro = None
    if args.calibration:
        _warn_if_calibration_misfits(model, t, accel_g)
    settings = FilterSettings(still_time_constant_s=args.still_time_constant_s,
                              moving_time_constant_s=args.moving_time_constant_s,
                              platform_accel_g=args.platform_accel_g)
    estimates = estimate_series(t, accel_g, gyro, odometry, args.lever_arm, model,
                                float(tilt_std), settings=settings,
                                time_constant_s=args.time_constant_s,
                                accel_threshold_g=args.accel_threshold_g)
    skipped = sum(est is None for est in estimates)
    if skipped == len(estimates):
        raise InputError(f'{args.recording}: no usable sample: all {skipped} are impossible '
                         '(NaN or infinite, all zero, or a calibrated magnitude outside '
                         f'{MIN_FORCE_G:g}..{MAX_FORCE_G:g} g); nothing written')
    aided = ''
    if odometry is not None:
        share = odometry_coverage(t, odometry[0])
        aided = ', odometry-aided' + (f' ({share:.0%} of the samples)' if share < 1 else '')
    print(f'note: {"gyro-aided" if gyro is not None else "accelerometer only"}{aided}',
          file=sys.stderr)
    note = (f' ({skipped} impossible sample(s) skipped: NaN or infinite, all zero, or a '
            f'calibrated magnitude outside {MIN_FORCE_G:g}..{MAX_FORCE_G:g} g)'
            if skipped else '')
    lines = ['t,roll_deg,pitch_deg,roll_std_deg,pitch_std_deg,accelerating']
    deg = math.degrees
    for k, (ti, est) in enumerate(zip(t.tolist(), estimates)):
        if k % args.every or est is None:
            continue
        var_roll, _, var_pitch = est.cov
        lines.append(f'{ti:.6f},{deg(est.roll):.4f},{deg(est.pitch):.4f},'
                     f'{deg(math.sqrt(var_roll)):.4f},{deg(math.sqrt(var_pitch)):.4f},'
                     f'{int(est.accelerating)}')
    text = '\n'.join(lines) + '\n'
    if args.output:
        write_text_atomic(args.output, text)
        print(f'wrote {len(lines) - 1} rows to {args.output}{note}')
    else:
        sys.stdout.write(text)
        if note:
            print(f'note: {note[2:-1]}', file=sys.stderr)
    return 0


def _read_attitude_input(args):
    """Return ``(t, accel g, gyro rad/s or None)`` of a CSV (gx,gy,gz optional) or a bag."""
    from accelcal_ros.recording.bag import is_bag

    if is_bag(args.recording):
        from accelcal_ros.recording.cli_support import open_bag, warn
        from accelcal_ros.recording.streams import read_imu

        with open_bag(args.recording, args.stamp) as bag:
            imu = read_imu(bag, args.topic)
        warn(imu.warnings)
        return imu.t, imu.accel / STANDARD_GRAVITY, imu.gyro
    return _read_csv_recording(args)


def _plot(args):
    from accelcal_ros.calibration.plot import plot_calibration_file
    from accelcal_ros.outputs import check_output_path, PNG_SUFFIXES

    check_output_path(args.output, '-o', PNG_SUFFIXES)
    plot_calibration_file(args.output, args.calibration)
    print(f'wrote {args.output}')
    return 0


def _study(args):
    from accelcal_ros.calibration import study

    trials = 20 if args.quick else args.trials
    counts = (6, 12, 100) if args.quick else study.POSITION_COUNTS
    for line in study.format_worked_example(study.paper_worked_example()):
        print(line)
    print()
    rows = study.run_study(trials=trials, seed=args.seed, counts=counts)
    print()
    study.run_real_like(trials=trials, seed=args.seed)
    target = [r for r in rows if r['positions'] == 12 and r['layout'] == 'recommended'
              and r['samples'] == 100 and r['model'] == 'full' and r['fitted']]
    if target:
        p95 = target[0]['tilt_p95_deg']
        print(f'\nTarget: K=12 recommended positions, 1 s each, full model: roll/pitch p95 '
              f'{p95:.3f} deg ({"meets" if p95 < 0.1 else "MISSES"} < 0.1 deg; paper A: '
              '1.5-3 deg at K=100-300)')
    return 0
