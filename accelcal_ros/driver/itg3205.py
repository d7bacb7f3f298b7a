"""
The ITG-3205 three-axis gyro (GY-85 board, I2C 0x68 or 0x69) over smbus2 (pure core).

Register map (InvenSense ITG-3205 product specification, rev. 1.0, section 8):

* ``WHO_AM_I`` (0x00): bits 6-1 hold 110100b; it reads 0x68 (AD0 low) or 0x69 (AD0
  high; bit 0 is the AD0 level on some parts). Anything else is another chip: refused.
* ``SMPLRT_DIV`` (0x15): ``F_sample = F_internal / (div + 1)``, ``F_internal`` 1 kHz
  with the low-pass filter on (8 kHz with ``DLPF_CFG`` = 0).
* ``DLPF_FS`` (0x16): ``FS_SEL`` (bits 4-3) must be 3 (+-2000 deg/s, the only full
  scale the part supports); ``DLPF_CFG`` (bits 2-0): low-pass bandwidth 256, 188, 98, 42,
  20, 10, 5 Hz.
* ``INT_STATUS`` (0x1A): bit 0 ``RAW_DATA_RDY``.
* ``TEMP_OUT_H/L`` (0x1B-0x1C), ``GYRO_XOUT_H`` ... ``GYRO_ZOUT_L`` (0x1D-0x22): big-endian
  two's complement; 14.375 LSB per deg/s; temperature ``35 + (raw + 13200) / 280`` deg C.
* ``PWR_MGM`` (0x3E): bit 7 ``H_RESET``, bit 6 ``SLEEP``, ``CLK_SEL`` (bits 2-0): 1 = PLL
  with the X gyro as reference (recommended).

The part has no FIFO: :meth:`Itg3205.read_rate_rad_s` reads the newest sample (one block
read of the 8 data bytes, so temperature and the three axes belong together); the
caller stamps it at the read. Rates are returned in rad/s in the sensor's axes
(REP-103 frames are the board's job: on the GY-85 the gyro's axes are the ADXL345's).
"""
import math
from typing import Any, Optional, Tuple

from accelcal_ros.errors import DeviceError, InputError
from accelcal_ros.sensor.gyro_sampling import (  # noqa: F401 (part of this module's API)
    DLPF_BANDWIDTHS_HZ, DLPF_DELAY_S, dlpf_for_rate)

WHO_AM_I = 0x00
SMPLRT_DIV = 0x15
DLPF_FS = 0x16
INT_CFG = 0x17
INT_STATUS = 0x1A
TEMP_OUT_H = 0x1B
GYRO_XOUT_H = 0x1D
PWR_MGM = 0x3E

WHO_AM_I_VALUES = (0x68, 0x69)
"""What WHO_AM_I reads on an ITG-3205 (AD0 low / high)."""
VALID_ADDRESSES = (0x68, 0x69)
FS_SEL_2000 = 0x18
"""``FS_SEL`` = 3 in DLPF_FS (bits 4-3): the only valid full scale."""
LSB_PER_DEG_S = 14.375
FULL_SCALE_RAD_S = math.radians(2000.0)
RAW_DATA_RDY = 0x01
H_RESET = 0x80
CLK_PLL_X = 0x01
NOISE_RMS_DEG_S = 0.38
"""Total rms noise at 100 Hz bandwidth (product specification, table 2)."""


def sample_rate_divider(rate_hz: float) -> int:
    """Return SMPLRT_DIV for ``rate_hz`` from the 1 kHz internal rate (InputError if none)."""
    if not (math.isfinite(rate_hz) and 3.9 <= rate_hz <= 1000.0):
        raise InputError(f'ITG-3205 sample rate must be 3.9-1000 Hz (1 kHz / (div + 1)), '
                         f'got {rate_hz!r}')
    divider = round(1000.0 / rate_hz) - 1
    if abs(1000.0 / (divider + 1) - rate_hz) > 1e-6 * rate_hz:
        raise InputError(f'ITG-3205 sample rate {rate_hz:g} Hz is not 1 kHz / an integer '
                         '(e.g. 100, 200, 250, 500, 1000 Hz)')
    return divider


def _int16(high: int, low: int) -> int:
    value = (high << 8) | low
    return value - 65536 if value & 0x8000 else value


class Itg3205:
    """One ITG-3205 on an smbus2-like ``bus`` (read/write_byte_data, read_i2c_block_data)."""

    def __init__(self, bus: Any, address: int = 0x68, bus_number: Optional[int] = None) -> None:
        if address not in VALID_ADDRESSES:
            raise InputError(f'ITG-3205 I2C address must be 0x68 or 0x69, got 0x{address:02X}')
        self.bus = bus
        self.address = address
        self.bus_number = bus_number
        self.rate_hz = float('nan')
        self.bandwidth_hz = float('nan')
        self.delay_s = 0.0

    def _where(self) -> str:
        bus = f'I2C bus {self.bus_number}, ' if self.bus_number is not None else ''
        return f'ITG-3205 ({bus}address 0x{self.address:02X})'

    def check_device_id(self) -> None:
        """Read WHO_AM_I; DeviceError naming the value read unless 0x68/0x69."""
        try:
            value = self.bus.read_byte_data(self.address, WHO_AM_I)
        except OSError as exc:
            raise DeviceError(f'{self._where()}: cannot read WHO_AM_I ({exc.strerror or exc}); '
                              'check wiring, power and the address (GY-85: 0x68)') from None
        if (value & 0x7E) != 0x68:
            raise DeviceError(f'{self._where()}: WHO_AM_I read 0x{value:02X}, expected 0x68 or '
                              '0x69: not an ITG-3205 (wrong address or another chip)')

    def configure(self, rate_hz: float, max_bandwidth_hz: Optional[float] = None) -> None:
        """
        Reset, select the PLL clock, +-2000 deg/s, the low-pass, the rate ``rate_hz``.

        The low-pass is the widest below half the sample rate and below
        ``max_bandwidth_hz`` (half the rate at which the caller reads: what it does not
        read would alias); :attr:`delay_s` is its group delay.
        """
        divider = sample_rate_divider(rate_hz)
        limit = rate_hz if max_bandwidth_hz is None else min(rate_hz, 2.0 * max_bandwidth_hz)
        code = dlpf_for_rate(limit)
        self.check_device_id()
        write = self.bus.write_byte_data
        try:
            write(self.address, PWR_MGM, H_RESET)
            write(self.address, PWR_MGM, CLK_PLL_X)
            write(self.address, DLPF_FS, FS_SEL_2000 | code)
            write(self.address, SMPLRT_DIV, divider)
            write(self.address, INT_CFG, 0x00)
            read_back = self.bus.read_byte_data(self.address, DLPF_FS)
        except OSError as exc:
            raise DeviceError(f'{self._where()}: configuration failed ({exc.strerror or exc})') \
                from None
        if read_back & 0x18 != FS_SEL_2000:
            raise DeviceError(f'{self._where()}: DLPF_FS read back 0x{read_back:02X}: the full '
                              'scale did not take (bus problem?)')
        self.rate_hz = 1000.0 / (divider + 1)
        self.bandwidth_hz = DLPF_BANDWIDTHS_HZ[code]
        self.delay_s = DLPF_DELAY_S[code]

    def data_ready(self) -> bool:
        """Return whether a new sample is ready (INT_STATUS.RAW_DATA_RDY)."""
        return bool(self.bus.read_byte_data(self.address, INT_STATUS) & RAW_DATA_RDY)

    def read_raw(self) -> Tuple[int, int, int, int]:
        """Return ``(temperature, x, y, z)`` raw counts from one 8-byte block read."""
        data = self.bus.read_i2c_block_data(self.address, TEMP_OUT_H, 8)
        if len(data) != 8:
            raise OSError(f'short read of {len(data)} bytes')
        return (_int16(data[0], data[1]), _int16(data[2], data[3]), _int16(data[4], data[5]),
                _int16(data[6], data[7]))

    def read_rate_rad_s(self) -> Tuple[float, float, float]:
        """Return the angular velocity (rad/s, sensor axes) of the newest sample."""
        _, x, y, z = self.read_raw()
        scale = math.radians(1.0) / LSB_PER_DEG_S
        return x * scale, y * scale, z * scale

    def read_temperature_c(self) -> float:
        """Return the die temperature (deg C)."""
        return 35.0 + (self.read_raw()[0] + 13200) / 280.0

    @staticmethod
    def saturated(rate_rad_s: Tuple[float, float, float]) -> bool:
        """Return whether any axis sits at the full scale (the reading is clipped)."""
        limit = FULL_SCALE_RAD_S * (1.0 - 1e-3)
        return any(abs(v) >= limit for v in rate_rad_s)
