"""
The GY-85's ITG-3205 gyro beside the ADXL345 in ``imu_driver`` (pure core, no ROS).

:func:`make_gyro` builds it from the driver's parameters (``gyro: itg3205``): on the I2C
bus of the accelerometer at ``gyro_i2c_address`` (0x68 on the GY-85), or, with the sim
backend, a register-level simulated ITG-3205 (:mod:`~accelcal_ros.driver.itg3205_sim`)
whose true rate is that of the simulated accelerometer's motion (the body rates of its
roll/pitch schedule), with a bias, a 1 % scale error and the datasheet noise.

The ITG-3205 has no FIFO: :meth:`GyroReader.read` returns its newest sample, read once
per batch of accelerometer samples and given to every sample of the batch (the batch
spans at most one poll: 1 ms at 3200 Hz, 10 ms at 100 Hz, FIFO drains of up to 32
samples at 800 Hz: 40 ms). A read error gives None (the samples go out without angular
velocity, covariance[0] = -1) and is counted; a saturated axis is counted and flagged.
"""
import math
from typing import Any, Mapping, Optional, Tuple

from accelcal_ros.driver.itg3205 import Itg3205, NOISE_RMS_DEG_S
from accelcal_ros.errors import InputError

GYRO_CHOICES = ('none', 'itg3205')
SIM_BIAS_RAD_S = (0.012, -0.009, 0.006)
"""Bias of the simulated gyro (rad/s; an ITG-3205 is specified at up to +-40 deg/s)."""


def gyro_rate_hz(accel_rate_hz: float) -> float:
    """Return the ITG-3205 rate (1 kHz / integer) nearest at or above the accelerometer's."""
    divider = max(0, int(math.ceil(1000.0 / min(accel_rate_hz, 1000.0) - 1e-9)) - 1)
    return 1000.0 / (divider + 1)


class GyroReader:
    """An :class:`Itg3205` read once per batch; counts errors and saturations."""

    def __init__(self, device: Itg3205, rate_hz: float) -> None:
        self.device = device
        device.configure(gyro_rate_hz(rate_hz))
        self.rate_hz = device.rate_hz
        self.errors = 0
        self.saturated = 0
        self.last_error = ''
        self.variance = math.radians(NOISE_RMS_DEG_S) ** 2

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
        return GyroReader(Itg3205(bus, address), values['rate_hz'])
    if backend == 'replay':
        raise InputError('gyro: itg3205 needs the i2c or sim backend (a replay CSV has no '
                         'gyro registers)')
    from accelcal_ros.driver.adxl345 import open_smbus

    i2c = open_smbus(values['i2c_bus'])
    return GyroReader(Itg3205(i2c, address, values['i2c_bus']), values['rate_hz'])
