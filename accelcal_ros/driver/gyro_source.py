"""
The GY-85's ITG-3205 gyro beside the ADXL345 in ``imu_driver`` (pure core, no ROS).

:func:`make_gyro` builds it from the driver's parameters (``gyro: itg3205``): on the I2C
bus of the accelerometer at ``gyro_i2c_address`` (0x68 on the GY-85), or, with the sim
backend, a register-level simulated ITG-3205 (:mod:`~accelcal_ros.driver.itg3205_sim`)
whose true rate is that of the simulated accelerometer's motion (the body rates of its
roll/pitch schedule), with a bias, a 1 % scale error and the datasheet noise.

The ITG-3205 has no FIFO: it samples at 1 kHz and is read once per poll of the
accelerometer (FIFO drains every two samples: 20 ms at 100 Hz, 2.5 ms at 800 Hz), so
its low-pass is set below half the poll rate (what is not read would alias: 20 Hz for
20 ms polls, 188 Hz for 2.5 ms ones; :mod:`accelcal_ros.sensor.gyro_sampling`).
:meth:`GyroReader.read_stamped` stamps each read at the read time minus that low-pass's
group delay, and :meth:`GyroReader.rates_at` gives
each accelerometer sample of the batch the rate interpolated at its stamp between the
last two reads (the line continued over the low-pass delay after the newest one, then
held). A read error gives None (the
samples go out without angular velocity, covariance[0] = -1) and is counted; a
saturated axis is counted and flagged.
"""
from collections import deque
import math
import time
from typing import Any, Callable, Deque, List, Mapping, Optional, Sequence, Tuple

from accelcal_ros.driver.itg3205 import Itg3205, NOISE_RMS_DEG_S
from accelcal_ros.errors import InputError
from accelcal_ros.sensor.gyro_sampling import rates_at

GYRO_CHOICES = ('none', 'itg3205')
SIM_BIAS_RAD_S = (0.012, -0.009, 0.006)
"""Bias of the simulated gyro (rad/s; an ITG-3205 is specified at up to +-40 deg/s)."""


def gyro_rate_hz(accel_rate_hz: float) -> float:
    """
    Return the ITG-3205 sample rate: 1 kHz, whatever the accelerometer's.

    Read once per poll, the newest sample is then at most 1 ms old; the low-pass (set
    from the poll rate) is what keeps the reads from aliasing.
    """
    return 1000.0


class GyroReader:
    """An :class:`Itg3205` read once per poll; stamped reads; counts errors and saturations."""

    def __init__(self, device: Itg3205, rate_hz: float, poll_period_s: Optional[float] = None,
                 clock: Callable[[], float] = time.time) -> None:
        self.device = device
        device.configure(gyro_rate_hz(rate_hz),
                         None if not poll_period_s else 0.5 / poll_period_s)
        self.rate_hz = device.rate_hz
        self.clock = clock
        self.errors = 0
        self.saturated = 0
        self.last_error = ''
        # the datasheet's rms is at 100 Hz bandwidth; white noise scales with its root
        bandwidth = device.bandwidth_hz if math.isfinite(device.bandwidth_hz) else 100.0
        self.variance = math.radians(NOISE_RMS_DEG_S) ** 2 * bandwidth / 100.0
        self._reads: Deque[Tuple[float, float, float, float]] = deque(maxlen=2)

    def read_stamped(self, now: Optional[float] = None) -> Optional[Tuple[float, float, float]]:
        """Read (:meth:`read`) and keep it stamped at ``now`` minus the low-pass delay."""
        rate = self.read()
        if rate is not None:
            t = (self.clock() if now is None else now) - self.device.delay_s
            self._reads.append((t, rate[0], rate[1], rate[2]))
        return rate

    def rates_at(self, stamps: Sequence[float]) -> List[Tuple[float, float, float]]:
        """Return the rate at each stamp (s): the line through the last two reads."""
        return rates_at(self._reads, stamps, self.device.delay_s, 1.0 / self.rate_hz)

    def read(self) -> Optional[Tuple[float, float, float]]:
        """Return the newest angular velocity (rad/s) or None after a bus error."""
        try:
            rate = self.device.read_rate_rad_s()
        except OSError as exc:
            self.errors += 1
            self.last_error = f'ITG-3205 read: {exc.strerror or exc}'
            return None
        if Itg3205.saturated(rate):
            self.saturated += 1
        return rate


def poll_period_of(source: Any) -> Optional[float]:
    """Return the accelerometer source's poll period (s), or None if it has none."""
    period = getattr(source, 'poll_period', None)
    if period is None and hasattr(source, 'period'):
        period = getattr(source, 'batch', 1) * source.period
    return float(period) if period else None


def _body_rates(sensor: Any) -> Any:
    """Return ``rate_of(t)``: body angular velocity (rad/s) of a simulated ADXL345's motion."""
    step = 1e-3

    def rate_of(t: float) -> Tuple[float, float, float]:
        roll, pitch = sensor.attitude_at([t - step, t + step])
        d_roll = (roll[1] - roll[0]) / (2 * step)
        d_pitch = (pitch[1] - pitch[0]) / (2 * step)
        r = 0.5 * (roll[0] + roll[1])
        return d_roll, d_pitch * math.cos(r), -d_pitch * math.sin(r)   # yaw rate 0
    return rate_of


def make_gyro(values: Mapping[str, Any], source: Any) -> Optional[GyroReader]:
    """Return the gyro for validated driver ``values`` (None for ``gyro: none``)."""
    kind = values.get('gyro', 'none')
    if kind == 'none':
        return None
    if kind != 'itg3205':
        raise InputError(f'gyro must be one of {GYRO_CHOICES}, got {kind!r}')
    address = values['gyro_i2c_address']
    backend = values['backend']
    if backend == 'sim':
        from accelcal_ros.driver.itg3205_sim import SimulatedItg3205Bus
        import time

        # the sample-level simulator, or the one behind the register-level chip (sim.bus)
        sensor = source.sensor if hasattr(source, 'sensor') else source.sim_chip.source
        start = time.time()
        bus = SimulatedItg3205Bus(_body_rates(sensor), address, SIM_BIAS_RAD_S,
                                  (1.01, 0.99, 1.005),
                                  NOISE_RMS_DEG_S * values['sim.noise_scale'],
                                  clock=lambda: time.time() - start, seed=values['seed'])
        return GyroReader(Itg3205(bus, address), values['rate_hz'], poll_period_of(source))
    if backend == 'replay':
        raise InputError('gyro: itg3205 needs the i2c or sim backend (a replay CSV has no '
                         'gyro registers)')
    from accelcal_ros.driver.adxl345 import open_smbus

    i2c = open_smbus(values['i2c_bus'])
    return GyroReader(Itg3205(i2c, address, values['i2c_bus']), values['rate_hz'],
                      poll_period_of(source))
