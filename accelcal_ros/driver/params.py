"""Parameters of the ``imu_driver`` node (pure: specifications and source construction)."""
from typing import Any, Mapping, Tuple, TYPE_CHECKING, Union

from accelcal_ros.driver import adxl345_registers as reg
from accelcal_ros.driver import bus_timing
from accelcal_ros.driver.adxl345 import Adxl345
from accelcal_ros.driver.sim_sensor import poses_from_flat_list, SimulatedAdxl345
from accelcal_ros.driver.transport import (I2cTransport, linux_bus_speed_hz, setup_spi,
                                           SpiTransport)
from accelcal_ros.errors import InputError
from accelcal_ros.paramspec import ParamSpec
from accelcal_ros.sensor.datasheet import OUTPUT_DATA_RATES_HZ, RANGES_G
from accelcal_ros.sensor.model import PAPER_K500_BIAS, PAPER_K500_SCALE, SensorModel

if TYPE_CHECKING:  # the sources are imported when one is built
    from accelcal_ros.driver.sources import Adxl345Source, ReplaySource, SimSource


def _poses_reason(values):
    if len(values) % 2:
        return 'needs (roll, pitch) pairs in degrees: an even number of values'
    if any(abs(v) > 180.0 for v in values[0::2]) or any(abs(v) > 90.0 for v in values[1::2]):
        return 'roll must be within +-180 deg and pitch within +-90 deg'
    return None


def _non_empty(value):
    return None if value.strip() else 'must not be empty'


def _frame_id_reason(value):
    """Why ``value`` is no tf2 frame id, or None (frame_tree loads scipy: on use)."""
    if not value.strip():
        return 'must not be empty'
    from accelcal_ros.frame_tree import frame_id_reason

    return frame_id_reason(value)


def _speed_reason(value):
    if value != 0.0 and value < bus_timing.BUS_MIN_HZ:
        return f'0 (auto) or at least {bus_timing.BUS_MIN_HZ:g} Hz'
    return None


def _axes_reason(value):
    return None if set(value) <= set('xyz') else 'letters of xyz only, e.g. "z"'


DRIVER_PARAMS = (
    ParamSpec('backend', 'i2c', 'Sample source: i2c (ADXL345 via smbus2), spi (ADXL345 via '
              'spidev, 4-wire, mode 3), sim (simulated ADXL345; sim.bus chooses sample or '
              'register level), replay (CSV recording t,ax,ay,az in s and m/s^2).',
              choices=('i2c', 'spi', 'sim', 'replay'), read_only=True),
    ParamSpec('i2c_bus', 1, 'I2C bus number N of /dev/i2c-N.', minimum=0, maximum=255,
              read_only=True),
    ParamSpec('i2c_address', 0x53, 'ADXL345 I2C address: 0x53 (83, ALT ADDRESS low) or '
              '0x1D (29, ALT ADDRESS high).', choices=reg.VALID_ADDRESSES, read_only=True),
    ParamSpec('spi_bus', 0, 'SPI bus B of /dev/spidevB.C (backend spi).', minimum=0,
              maximum=255, read_only=True),
    ParamSpec('spi_device', 0, 'SPI chip select C of /dev/spidevB.C (backend spi).',
              minimum=0, maximum=255, read_only=True),
    ParamSpec('bus_speed_hz', 0.0, 'Bus clock: 0 = what Linux says (I2C clock-frequency, SPI '
              'spi-max-frequency of the device tree), else 100 kHz on I2C, 5 MHz on SPI. I2C: '
              'used where Linux says nothing (the kernel sets the I2C clock); SPI: the clock '
              'spidev asks for; sim: the simulated bus clock. ADXL345 limits: I2C 400 kHz, SPI '
              '5 MHz.', kind='double', minimum=0.0, maximum=5e6, validator=_speed_reason,
              read_only=True, unit='Hz'),
    ParamSpec('allow_unsustainable_rate', False, 'Run a rate_hz the bus cannot sustain '
              '(datasheet rule, bus time) instead of refusing; the achieved rate and the '
              'lost samples are then reported in /diagnostics.', read_only=True),
    ParamSpec('reads', 'polling', 'How the FIFO is drained: polling (on a timer), or '
              'interrupt (the FIFO watermark on INT1 through a GPIO line, libgpiod; stamps '
              'at the edge; polling when no edge comes). sim: the simulated INT1 line.',
              choices=('polling', 'interrupt'), read_only=True),
    ParamSpec('int1_gpio_chip', 'gpiochip0', 'GPIO chip (/dev/<name>) INT1 is wired to '
              '(reads interrupt).', validator=_non_empty, read_only=True),
    ParamSpec('int1_gpio_line', 0, 'GPIO line offset on int1_gpio_chip INT1 is wired to '
              '(e.g. the BCM number on a Raspberry Pi).', minimum=0, maximum=1023,
              read_only=True),
    ParamSpec('supply_voltage_v', 3.3, 'ADXL345 supply voltage VS: scales the self-test '
              'limits (datasheet Table 14).', minimum=2.0, maximum=3.6, read_only=True,
              unit='V'),
    ParamSpec('range_g', 16, 'Measurement range +-g (full resolution: 3.9 mg/LSB at every '
              'range; a larger range only moves saturation).', choices=RANGES_G,
              read_only=True, unit='g'),
    ParamSpec('rate_hz', 100.0, 'Output data rate of the ADXL345.', kind='double',
              choices=OUTPUT_DATA_RATES_HZ, read_only=True, unit='Hz'),
    ParamSpec('fifo', 'auto', 'FIFO use: auto (stream mode above 100 Hz, where single reads '
              'cannot keep up), always, never. (Not on/off: YAML reads those as booleans.)',
              choices=('auto', 'always', 'never'), read_only=True),
    ParamSpec('frame_id', 'imu_link', 'frame_id of published messages (REP-103 body frame of '
              'the sensor).', validator=_frame_id_reason),
    ParamSpec('seed', 0, 'Random seed of the simulated sensor (deterministic samples).',
              minimum=0, maximum=2**31 - 1, read_only=True),
    ParamSpec('sim.poses_deg', [], 'Simulated static orientations: flat list of roll, pitch '
              'pairs in degrees (REP-103); empty: 24 built-in near-uniform orientations.',
              kind='double_array', validator=_poses_reason, read_only=True, unit='deg'),
    ParamSpec('sim.dwell_s', 3.0, 'Time the simulated sensor stays still in each orientation.',
              minimum=0.05, maximum=3600.0, read_only=True, unit='s'),
    ParamSpec('sim.move_s', 1.0, 'Time of the smooth turn between orientations.',
              minimum=0.0, maximum=3600.0, read_only=True, unit='s'),
    ParamSpec('sim.scale', list(PAPER_K500_SCALE), 'True scale factors k of the simulated '
              'sensor (default: paper A Table 1, K=500).', lengths=(3,), minimum=0.1,
              maximum=10.0, read_only=True),
    ParamSpec('sim.bias', list(PAPER_K500_BIAS), 'True biases b of the simulated sensor, in g '
              '(default: paper A Table 1, K=500).', lengths=(3,), minimum=-2.0, maximum=2.0,
              read_only=True, unit='g'),
    ParamSpec('sim.misalignment', [0.0, 0.0, 0.0], 'True axis misalignment [m_yz, m_zy, '
              'm_zx] of the simulated sensor (full model).', lengths=(3,), minimum=-0.1,
              maximum=0.1, read_only=True, unit='rad'),
    ParamSpec('sim.noise_scale', 1.0, 'Multiplier of the datasheet noise of the simulated '
              'sensor (0: noise-free).', minimum=0.0, maximum=100.0, read_only=True),
    ParamSpec('sim.bus', 'none', 'Simulation level: none (sample-level sensor, no bus), i2c '
              'or spi (register-level ADXL345 whose every transaction costs its time on the '
              'wire at bus_speed_hz, driven by the same code as the real buses).',
              choices=('none', 'i2c', 'spi'), read_only=True),
    ParamSpec('sim.self_test_broken_axes', '', 'Axes (letters of xyz) whose simulated '
              'self-test force is missing (a broken sensor); empty: healthy.',
              validator=_axes_reason, read_only=True),
    ParamSpec('replay.file', '', 'CSV recording to publish (backend replay).', read_only=True),
    ParamSpec('replay.realtime', True, 'Replay with the recorded timing (false: as fast as '
              'possible).', read_only=True),
    ParamSpec('gyro', 'none', "Gyro beside the ADXL345: none, or itg3205 (the GY-85 board's "
              'ITG-3205 on the same I2C bus; simulated with the sim backend): angular velocity '
              'and its covariance in imu/data_raw.', choices=('none', 'itg3205'),
              read_only=True),
    ParamSpec('gyro_i2c_address', 0x68, 'ITG-3205 I2C address: 0x68 (104, GY-85) or 0x69 '
              '(105).', choices=(0x68, 0x69), read_only=True),
    ParamSpec('diagnostics_period_s', 1.0, 'Period of /diagnostics messages.', minimum=0.1,
              maximum=60.0, unit='s'),
)


DEFAULT_SPEED_HZ = {'i2c': 100_000.0, 'spi': 5_000_000.0}
"""Bus clock where neither Linux nor bus_speed_hz says (Raspberry Pi I2C default; SPI max)."""


def bus_speed_hz(values: Mapping[str, Any], sysfs: str = '/sys') -> Tuple[str, float]:
    """
    Return ``(bus, clock in Hz)`` for the i2c, spi or register-level sim backend.

    I2C: Linux's ``clock-frequency`` where the device tree gives it (the kernel, not
    userspace, sets it), else ``bus_speed_hz``, else 100 kHz. SPI: ``bus_speed_hz`` or
    5 MHz, lowered to the device tree's ``spi-max-frequency``. Sim: ``bus_speed_hz`` or the
    bus's default. InputError when the clock is outside the ADXL345's range.
    """
    backend = values['backend']
    bus = values['sim.bus'] if backend == 'sim' else backend
    speed = float(values['bus_speed_hz']) or DEFAULT_SPEED_HZ[bus]
    if backend == 'i2c':
        linux = linux_bus_speed_hz('i2c', values['i2c_bus'], sysfs=sysfs)
        speed = linux or float(values['bus_speed_hz']) or DEFAULT_SPEED_HZ['i2c']
    elif backend == 'spi':
        linux = linux_bus_speed_hz('spi', values['spi_bus'], values['spi_device'], sysfs)
        if linux is not None and linux < speed:
            speed = linux
    reason = bus_timing.check_speed(bus, speed)
    if reason:
        raise InputError(reason)
    return bus, speed


def use_fifo(values: Mapping[str, Any]) -> bool:
    """Stream mode per the ``fifo`` parameter (auto: above 100 Hz)."""
    return {'always': True, 'never': False}.get(values['fifo'], values['rate_hz'] > 100.0)


def check_rate(values: Mapping[str, Any], bus: str, speed: float) -> str:
    """
    Return the reason ``rate_hz`` is not sustainable ('' if it is).

    Raises InputError with it unless ``allow_unsustainable_rate`` (then the node warns).
    """
    reason = bus_timing.check_rate(bus, speed, values['rate_hz'], use_fifo(values)) or ''
    if reason and not values['allow_unsustainable_rate']:
        raise InputError(reason + ' (allow_unsustainable_rate:=true runs it anyway)')
    return reason


def make_register_sim(values: Mapping[str, Any], sensor: SimulatedAdxl345, bus: str,
                      speed: float) -> Any:
    """Return the register-level simulated ADXL345 on ``bus`` (healthy or broken axes)."""
    from accelcal_ros.driver.register_sim import SimulatedAdxl345Bus, SimulatedAdxl345Spi
    from accelcal_ros.driver.selftest import self_test_scale

    shift = [0.0 if axis in values['sim.self_test_broken_axes'] else 1.0 for axis in 'xyz']
    scale = self_test_scale(values['supply_voltage_v']) * shift
    if bus == 'spi':
        device = SimulatedAdxl345Spi(sensor, self_test_scale=scale)
        setup_spi(device, speed)   # as open_spidev does on hardware
        return device
    return SimulatedAdxl345Bus(sensor, address=values['i2c_address'], bus_speed_hz=speed,
                               self_test_scale=scale)


def make_interrupt(values: Mapping[str, Any], sim_chip: Any = None) -> Any:
    """Return INT1 as an interrupt for ``reads:=interrupt`` (None: polling)."""
    from accelcal_ros.driver.gpio import GpiodInterrupt, SimulatedInterrupt

    if values['reads'] != 'interrupt':
        return None
    if sim_chip is not None:
        return SimulatedInterrupt(sim_chip)
    return GpiodInterrupt(values['int1_gpio_chip'], values['int1_gpio_line'])


def make_source(values: Mapping[str, Any], sysfs: str = '/sys'
                ) -> Union['SimSource', 'ReplaySource', 'Adxl345Source']:
    """
    Build the sample source for validated parameter ``values`` (may raise DeviceError).

    For the ADXL345 backends (i2c, spi, sim on a bus) the rate is checked against the
    bus first (:func:`check_rate`); the source's ``rate_warning`` holds the reason when
    ``allow_unsustainable_rate`` runs it anyway.
    """
    from accelcal_ros.driver.sources import Adxl345Source, ReplaySource, SimSource

    backend = values['backend']
    rate = values['rate_hz']
    if backend in ('i2c', 'spi') or (backend == 'sim' and values['sim.bus'] != 'none'):
        bus, speed = bus_speed_hz(values, sysfs)
        warning = check_rate(values, bus, speed)
    if backend == 'sim':
        truth = SensorModel(values['sim.scale'], values['sim.bias'], values['sim.misalignment'])
        sensor = SimulatedAdxl345(truth, rate, values['range_g'],
                                  poses_from_flat_list(values['sim.poses_deg']),
                                  values['sim.dwell_s'], values['sim.move_s'], values['seed'],
                                  values['sim.noise_scale'])
        if values['sim.bus'] == 'none':
            return SimSource(sensor)
        chip = make_register_sim(values, sensor, bus, speed)
        transport = (SpiTransport(chip, values['spi_bus'], values['spi_device']) if bus == 'spi'
                     else I2cTransport(chip, values['i2c_address'], values['i2c_bus']))
        source = Adxl345Source(Adxl345(transport), rate, values['range_g'], use_fifo(values),
                               bus_speed_hz=speed, interrupt=make_interrupt(values, chip))
        source.sim_chip = chip
        source.rate_warning = warning
        return source
    if backend == 'replay':
        if not values['replay.file']:
            raise InputError('backend replay needs replay.file (a CSV t,ax,ay,az)')
        return ReplaySource(values['replay.file'], values['replay.realtime'])
    interrupt = make_interrupt(values)
    if backend == 'spi':
        source = Adxl345Source.from_spi(values['spi_bus'], values['spi_device'], speed, rate,
                                        values['range_g'], use_fifo(values),
                                        interrupt=interrupt)
    else:
        source = Adxl345Source.from_bus_number(values['i2c_bus'], values['i2c_address'],
                                               rate, values['range_g'], use_fifo(values),
                                               bus_speed_hz=speed, interrupt=interrupt)
    source.rate_warning = warning
    return source
