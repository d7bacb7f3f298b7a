"""
``accelcal record``: record raw samples to CSV (``t,ax,ay,az``; s, m/s^2) without ROS.

From the simulated ADXL345 (default; same parameters as the node's sim backend) or a
real one over I2C, e.g.::

    accelcal record -o rec.csv --duration 60 --dwell 3 --move 1
    accelcal record -o rec.csv --backend i2c --bus 1 --rate 100 --duration 120
"""
from typing import Any

from accelcal_ros.cli_args import angle_deg, float_in, int_in, nonnegative_int


def register(subparsers: Any, study_subparsers: Any) -> None:
    """Add the ``record`` subcommand."""
    parser = subparsers.add_parser(
        'record', help='record raw accelerometer samples to CSV (sim or I2C)',
        description=__doc__.strip().splitlines()[0])
    parser.add_argument('-o', '--output', help='CSV file to write (or --bag)')
    _add_bag_arguments(parser)
    parser.add_argument('--backend', choices=('sim', 'i2c'), default='sim')
    parser.add_argument('--duration', type=float_in(0.0, 86400.0, low_open=True), default=30.0,
                        help='seconds (default 30)')
    parser.add_argument('--rate', type=float_in(0.0, 3200.0, low_open=True), default=100.0,
                        help='output data rate, Hz (ADXL345: up to 3200)')
    parser.add_argument('--range-g', type=int, default=16, choices=(2, 4, 8, 16))
    parser.add_argument('--bus', type=nonnegative_int, default=1, help='I2C bus number')
    parser.add_argument('--address', type=int_in(0, 0x7F), default=0x53,
                        help='I2C address (0x53 or 0x1D)')
    parser.add_argument('--poses-deg', type=angle_deg(360.0), nargs='*', default=[],
                        help='sim: roll pitch pairs in degrees (default: 24 built-in)')
    parser.add_argument('--dwell', type=float_in(0.0, 3600.0, low_open=True), default=3.0,
                        help='sim: dwell per pose, s')
    parser.add_argument('--move', type=float_in(0.0, 3600.0), default=1.0,
                        help='sim: move between poses, s')
    parser.add_argument('--seed', type=nonnegative_int, default=0, help='sim: random seed')
    parser.set_defaults(handler=_record)


def _record(args):
    import time

    from accelcal_ros.sensor.recording import save_recording
    from accelcal_ros.sensor.units import g_to_mps2
    from accelcal_ros.driver.sim_sensor import poses_from_flat_list, SimulatedAdxl345
    from accelcal_ros.driver.sources import I2cSource
    import numpy as np

    if args.duration <= 0:
        from accelcal_ros.errors import InputError
        raise InputError('--duration must be positive')
    start_s = _check_outputs(args)
    if args.backend == 'sim':  # simulated time: no need to wait
        sensor = SimulatedAdxl345(rate_hz=args.rate, range_g=args.range_g,
                                  poses_deg=poses_from_flat_list(args.poses_deg),
                                  dwell_s=args.dwell, move_s=args.move, seed=args.seed)
        t = np.arange(int(round(args.duration * args.rate))) / args.rate
        samples = sensor.read(t)
    else:
        source = I2cSource.from_bus_number(args.bus, args.address, args.rate, args.range_g,
                                           use_fifo=args.rate > 100.0)
        source.start()
        stamps, chunks = [], []
        end = time.time() + args.duration
        while time.time() < end:
            time.sleep(max(0.0, source.next_poll_time() - time.time()))
            batch = source.poll()
            stamps.append(batch.stamps)
            chunks.append(batch.samples_g)
        t = np.concatenate(stamps)
        t = t - t[0] if t.size else t
        samples = np.concatenate(chunks)
        if source.stats.io_errors:
            print(f'warning: {source.stats.io_errors} I2C errors, '
                  f'{source.stats.fifo_overruns} FIFO overruns during the recording')
    if args.bag:
        return _write_bag(args, start_s + t, g_to_mps2(samples))
    save_recording(args.output, t, g_to_mps2(samples))
    print(f'wrote {len(t)} samples ({args.duration:g} s at {args.rate:g} Hz) to {args.output}')
    return 0


def _add_bag_arguments(parser):
    """``record --bag``: a rosbag2 as the driver node would publish it."""
    parser.add_argument('--bag', metavar='DIR',
                        help='write a rosbag2 (mcap) instead of CSV: topic /imu/data_raw, '
                             'sensor_msgs/Imu, sensor-data QoS, frame and covariance as the '
                             'driver; `ros2 bag play DIR` replays it')
    parser.add_argument('--bag-format', choices=('mcap', 'sqlite3'), default='mcap',
                        help='rosbag2 storage of --bag (default mcap)')
    parser.add_argument('--frame-id', default='imu_link',
                        help='header.frame_id of --bag messages (default: the driver default)')


def _check_outputs(args):
    """Exactly one of -o/--bag; returns the wall-clock start (s) used for bag stamps."""
    import time

    from accelcal_ros.errors import InputError

    if bool(args.output) == bool(args.bag):
        raise InputError('record needs one output: -o FILE.csv or --bag DIR')
    if args.bag:
        import os

        if os.path.exists(args.bag):
            raise InputError(f'{args.bag} exists; remove it or choose another --bag')
    return time.time()


def _write_bag(args, t_s, accel_m_s2):
    """Write the samples (absolute s, m/s^2) as the driver publishes them."""
    from accelcal_ros.recording.writer import BagWriter, sensor_data_qos
    from accelcal_ros.sensor.datasheet import datasheet_noise_std_g
    from accelcal_ros.sensor.units import g_to_mps2
    import numpy as np

    std = g_to_mps2(datasheet_noise_std_g(args.rate))
    cov = np.diag(np.asarray(std, dtype=float) ** 2).reshape(9)
    topic = '/imu/data_raw'
    with BagWriter(args.bag, args.bag_format) as writer:
        writer.add_topic(topic, 'sensor_msgs/Imu', [sensor_data_qos()])
        for ti, ai in zip(t_s, accel_m_s2):
            ns = int(round(float(ti) * 1e9))
            writer.write(topic, ns, writer.imu_message(ns, ai, args.frame_id,
                                                       accel_covariance=cov, topic=topic))
    print(f'wrote {len(t_s)} samples ({args.duration:g} s at {args.rate:g} Hz) to {args.bag} '
          f'({args.bag_format}, {topic}, frame {args.frame_id})')
    return 0
