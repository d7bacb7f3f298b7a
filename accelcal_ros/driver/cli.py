"""
``accelcal record``: record raw samples to CSV (``t,ax,ay,az``; s, m/s^2) without ROS.

From the simulated ADXL345 (default; same parameters as the node's sim backend, in
simulated time; ``--sim-bus i2c|spi``: the register-level simulation in real time, bus time
charged) or a real one over I2C or SPI, e.g.::

    accelcal record -o rec.csv --duration 60 --dwell 3 --move 1
    accelcal record -o rec.csv --backend i2c --bus 1 --rate 100 --duration 120
    accelcal record -o rec.csv --backend spi --spi-bus 0 --rate 3200 --duration 10

The rate is checked against the bus as the node does (refused with the reason unless
``--allow-unsustainable-rate``). ``accelcal selftest`` runs the ADXL345's self-test.
"""
from typing import Any, Callable, Iterator, Tuple

from accelcal_ros.cli_args import angle_deg, float_in, int_in, nonnegative_int


MIN_RECORD_SAMPLES = 1
"""Fewest samples ``--duration`` x ``--rate`` may give (a recording with none is unreadable)."""


class _Accepted:
    """argparse ``choices`` given by a test, shown as words ("invalid choice: 1.0 (choose...")."""

    def __init__(self, accepts: Callable[[Any], bool], *shown: str) -> None:
        self.accepts, self.shown = accepts, shown

    def __contains__(self, value: object) -> bool:
        return self.accepts(value)

    def __iter__(self) -> Iterator[str]:
        return iter(self.shown)


def _bus_choices() -> Tuple[Tuple[float, ...], _Accepted, _Accepted]:
    """
    Return the ADXL345's ``(rates Hz, I2C addresses, bus speeds Hz)`` (the node's choices).

    A bus speed is 0 (auto) or at least ``bus_timing.BUS_MIN_HZ``, as ``bus_speed_hz``.
    """
    from accelcal_ros.driver.adxl345_registers import VALID_ADDRESSES
    from accelcal_ros.driver.bus_timing import BUS_MIN_HZ
    from accelcal_ros.sensor.datasheet import OUTPUT_DATA_RATES_HZ

    addresses = _Accepted(lambda v: v in VALID_ADDRESSES, *(hex(a) for a in VALID_ADDRESSES))
    speeds = _Accepted(lambda v: v == 0.0 or v >= BUS_MIN_HZ, '0 (auto)',
                       f'{BUS_MIN_HZ:g} Hz or more')
    return OUTPUT_DATA_RATES_HZ, addresses, speeds


def register(subparsers: Any, study_subparsers: Any) -> None:
    """Add the ``record`` subcommand."""
    rates, addresses, _ = _bus_choices()
    parser = subparsers.add_parser(
        'record', help='record raw accelerometer samples to CSV (sim, I2C or SPI)',
        description=__doc__.strip().splitlines()[0])
    parser.add_argument('-o', '--output', help='CSV file to write (or --bag)')
    _add_bag_arguments(parser)
    parser.add_argument('--backend', choices=('sim', 'i2c', 'spi'), default='sim')
    parser.add_argument('--duration', type=float_in(0.0, 86400.0, low_open=True), default=30.0,
                        help='seconds (default 30)')
    parser.add_argument('--rate', type=float_in(0.0, 3200.0, low_open=True), default=100.0,
                        choices=rates, metavar='HZ',
                        help='output data rate, Hz: an ADXL345 rate (6.25, 12.5, ... 3200: '
                             'doubling from 6.25; every backend, the simulations too)')
    parser.add_argument('--range-g', type=int, default=16, choices=(2, 4, 8, 16))
    parser.add_argument('--bus', type=int_in(0, 255), default=1, help='I2C bus number')
    parser.add_argument('--address', type=int_in(0, 0x7F), default=0x53, choices=addresses,
                        metavar='ADDR', help='I2C address (0x53 or 0x1D)')
    parser.add_argument('--poses-deg', type=angle_deg(360.0), nargs='*', default=[],
                        help='sim: roll pitch pairs in degrees (default: 24 built-in)')
    parser.add_argument('--dwell', type=float_in(0.0, 3600.0, low_open=True), default=3.0,
                        help='sim: dwell per pose, s')
    parser.add_argument('--move', type=float_in(0.0, 3600.0), default=1.0,
                        help='sim: move between poses, s')
    parser.add_argument('--seed', type=nonnegative_int, default=0, help='sim: random seed')
    _add_bus_arguments(parser)
    parser.add_argument('--allow-unsustainable-rate', action='store_true',
                        help='record a rate the bus cannot sustain (losses are reported)')
    parser.set_defaults(handler=_record)

    selftest = subparsers.add_parser(
        'selftest', help="run the ADXL345's built-in self-test (pass/fail per axis)",
        description='Run the ADXL345 self-test (datasheet: SELF_TEST bit, output change per '
                    'axis within Table 15 x Table 14 for the supply voltage); exit status 1 '
                    'when an axis fails. Sim: the register-level simulation (--sim-bus).')
    selftest.add_argument('--backend', choices=('sim', 'i2c', 'spi'), default='sim')
    selftest.add_argument('--bus', type=int_in(0, 255), default=1, help='I2C bus number')
    selftest.add_argument('--address', type=int_in(0, 0x7F), default=0x53, choices=addresses,
                          metavar='ADDR', help='I2C address (0x53 or 0x1D)')
    _add_bus_arguments(selftest, sim_bus_default='spi')
    selftest.add_argument('--supply-voltage', type=float_in(2.0, 3.6), default=3.3,
                          help='ADXL345 supply voltage VS, V (scales the limits; default 3.3)')
    selftest.add_argument('--sim-broken-axes', default='', metavar='AXES',
                          help='sim: axes (letters of xyz) whose self-test force is missing')
    selftest.set_defaults(handler=_selftest)


def _add_bus_arguments(parser, sim_bus_default='none'):
    """Bus options shared by record and selftest (the node's parameters of the same names)."""
    parser.add_argument('--sim-bus', choices=('none', 'i2c', 'spi'), default=sim_bus_default,
                        help='sim: none (sample level, simulated time) or the register-level '
                             'ADXL345 on i2c or spi, in real time with bus time charged')
    parser.add_argument('--bus-speed', type=float_in(0.0, 5e6), default=0.0,
                        choices=_bus_choices()[2], metavar='HZ',
                        help="bus clock, Hz: 0 (Linux's, else 100 kHz I2C / 5 MHz SPI) or "
                             '10000 to 5000000')
    parser.add_argument('--spi-bus', type=int_in(0, 255), default=0,
                        help='SPI bus B of /dev/spidevB.C')
    parser.add_argument('--spi-device', type=int_in(0, 255), default=0,
                        help='SPI chip select C of /dev/spidevB.C')


def _driver_values(args, **overrides):
    """Return the imu_driver parameters for these options (make_source builds from them)."""
    from accelcal_ros.driver.params import DRIVER_PARAMS

    values = {spec.name: spec.default for spec in DRIVER_PARAMS}
    values.update({'backend': args.backend, 'i2c_bus': args.bus, 'i2c_address': args.address,
                   'spi_bus': args.spi_bus, 'spi_device': args.spi_device,
                   'bus_speed_hz': float(args.bus_speed), 'sim.bus': args.sim_bus})
    values.update(overrides)
    for spec in DRIVER_PARAMS:   # the node's checks, with the parameter's name in the line
        _, reason = spec.check(values[spec.name])
        if reason:
            from accelcal_ros.errors import InputError
            raise InputError(reason)
    return values


def _selftest(args):
    from accelcal_ros.driver.params import make_source

    values = _driver_values(args, **{'rate_hz': 100.0, 'sim.poses_deg': [0.0, 0.0],
                                     'supply_voltage_v': float(args.supply_voltage),
                                     'sim.self_test_broken_axes': args.sim_broken_axes})
    if args.backend == 'sim' and args.sim_bus == 'none':
        values['sim.bus'] = 'spi'   # the self-test needs the registers
    source = make_source(values)
    source.start()
    result = source.self_test(args.supply_voltage)
    print(result.summary())
    return 0 if result.passed else 1


def _record(args):
    import time

    from accelcal_ros.sensor.recording import save_recording
    from accelcal_ros.sensor.units import g_to_mps2
    from accelcal_ros.driver.sim_sensor import poses_from_flat_list, SimulatedAdxl345
    import numpy as np

    start_s = _check_outputs(args)
    if args.backend == 'sim' and args.sim_bus == 'none':  # simulated time: no need to wait
        sensor = SimulatedAdxl345(rate_hz=args.rate, range_g=args.range_g,
                                  poses_deg=poses_from_flat_list(args.poses_deg),
                                  dwell_s=args.dwell, move_s=args.move, seed=args.seed)
        t = np.arange(int(round(args.duration * args.rate))) / args.rate
        samples = sensor.read(t)
    else:
        from accelcal_ros.driver.params import make_source

        values = _driver_values(args, **{
            'rate_hz': float(args.rate), 'range_g': args.range_g, 'seed': args.seed,
            'sim.poses_deg': [float(v) for v in args.poses_deg], 'sim.dwell_s': args.dwell,
            'sim.move_s': args.move, 'allow_unsustainable_rate': args.allow_unsustainable_rate})
        source = make_source(values)
        if source.rate_warning:
            print(f'warning: {source.rate_warning}')
        source.start()
        stamps, chunks = [], []
        end = time.time() + args.duration
        while time.time() < end:
            time.sleep(max(0.0, source.next_poll_time() - time.time()))
            batch = source.poll()
            stamps.append(batch.stamps)
            chunks.append(batch.samples_g)
        t = np.concatenate(stamps)
        if not t.size:
            from accelcal_ros.errors import DeviceError
            raise DeviceError(f'no sample arrived in {args.duration:g} s at {args.rate:g} Hz; '
                              'nothing written (record longer)')
        t = t - t[0]
        samples = np.concatenate(chunks)
        stats = source.stats
        if stats.io_errors or stats.fifo_overruns:
            print(f'warning: {stats.io_errors} {source.bus.upper()} errors, '
                  f'{stats.fifo_overruns} FIFO overruns ({source.lost_samples} samples lost, '
                  f'{source.overruns_bus} overrun(s) because the bus was too slow) during '
                  'the recording')
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
    """
    Check the outputs and the length before recording; return the wall-clock start (s).

    Exactly one of -o/--bag; ``--duration`` x ``--rate`` gives at least
    :data:`MIN_RECORD_SAMPLES` samples; a bag's ``--frame-id`` is a valid tf2 frame id
    (:func:`accelcal_ros.frame_tree.check_frame_id`, as the nodes check theirs).
    """
    import time

    from accelcal_ros.errors import InputError

    if bool(args.output) == bool(args.bag):
        raise InputError('record needs one output: -o FILE.csv or --bag DIR')
    if args.duration * args.rate < MIN_RECORD_SAMPLES * (1.0 - 1e-9):   # one sample period
        raise InputError(f'--duration {args.duration:g} s at --rate {args.rate:g} Hz gives no '
                         f'sample (needs at least {MIN_RECORD_SAMPLES / args.rate:g} s at this '
                         'rate)')
    if args.bag:
        import os

        from accelcal_ros.frame_tree import check_frame_id

        check_frame_id(args.frame_id, '--frame-id')
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
