"""Parameters of the ``imu_driver`` node (pure: specifications and source construction)."""
from typing import Any, Mapping, TYPE_CHECKING, Union

from accelcal_ros.driver import adxl345_registers as reg
from accelcal_ros.driver.sim_sensor import poses_from_flat_list, SimulatedAdxl345
from accelcal_ros.errors import InputError
from accelcal_ros.paramspec import ParamSpec
from accelcal_ros.sensor.datasheet import OUTPUT_DATA_RATES_HZ, RANGES_G
from accelcal_ros.sensor.model import PAPER_K500_BIAS, PAPER_K500_SCALE, SensorModel

if TYPE_CHECKING:  # the sources are imported when one is built
    from accelcal_ros.driver.sources import I2cSource, ReplaySource, SimSource


def _poses_reason(values):
    if len(values) % 2:
        return 'needs (roll, pitch) pairs in degrees: an even number of values'
    if any(abs(v) > 180.0 for v in values[0::2]) or any(abs(v) > 90.0 for v in values[1::2]):
        return 'roll must be within +-180 deg and pitch within +-90 deg'
    return None


def _non_empty(value):
    return None if value.strip() else 'must not be empty'


DRIVER_PARAMS = (
    ParamSpec('backend', 'i2c', 'Sample source: i2c (ADXL345 via smbus2), sim (simulated '
              'ADXL345), replay (CSV recording t,ax,ay,az in s and m/s^2).',
              choices=('i2c', 'sim', 'replay'), read_only=True),
    ParamSpec('i2c_bus', 1, 'I2C bus number N of /dev/i2c-N.', minimum=0, maximum=255,
              read_only=True),
    ParamSpec('i2c_address', 0x53, 'ADXL345 I2C address: 0x53 (83, ALT ADDRESS low) or '
              '0x1D (29, ALT ADDRESS high).', choices=reg.VALID_ADDRESSES, read_only=True),
    ParamSpec('range_g', 16, 'Measurement range +-g (full resolution: 3.9 mg/LSB at every '
              'range; a larger range only moves saturation).', choices=RANGES_G,
              read_only=True, unit='g'),
    ParamSpec('rate_hz', 100.0, 'Output data rate of the ADXL345.', kind='double',
              choices=OUTPUT_DATA_RATES_HZ, read_only=True, unit='Hz'),
    ParamSpec('fifo', 'auto', 'FIFO use: auto (stream mode above 100 Hz, where single reads '
              'cannot keep up), always, never. (Not on/off: YAML reads those as booleans.)',
              choices=('auto', 'always', 'never'), read_only=True),
    ParamSpec('frame_id', 'imu_link', 'frame_id of published messages (REP-103 body frame of '
              'the sensor).', validator=_non_empty),
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


def make_source(values: Mapping[str, Any]
                ) -> Union['SimSource', 'ReplaySource', 'I2cSource']:
    """Build the sample source for validated parameter ``values`` (may raise DeviceError)."""
    from accelcal_ros.driver.sources import I2cSource, ReplaySource, SimSource

    backend = values['backend']
    rate = values['rate_hz']
    if backend == 'sim':
        truth = SensorModel(values['sim.scale'], values['sim.bias'], values['sim.misalignment'])
        sensor = SimulatedAdxl345(truth, rate, values['range_g'],
                                  poses_from_flat_list(values['sim.poses_deg']),
                                  values['sim.dwell_s'], values['sim.move_s'], values['seed'],
                                  values['sim.noise_scale'])
        return SimSource(sensor)
    if backend == 'replay':
        if not values['replay.file']:
            raise InputError('backend replay needs replay.file (a CSV t,ax,ay,az)')
        return ReplaySource(values['replay.file'], values['replay.realtime'])
    use_fifo = {'always': True, 'never': False}.get(values['fifo'], rate > 100.0)
    return I2cSource.from_bus_number(values['i2c_bus'], values['i2c_address'], rate,
                                     values['range_g'], use_fifo)
