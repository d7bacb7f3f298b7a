"""
ADXL345 over I2C or SPI: device check, configuration, single and FIFO reads (pure, no ROS).

The bus is a :mod:`~accelcal_ros.driver.transport` (I2C: an object with smbus2's methods
``read_byte_data``, ``write_byte_data`` and ``read_i2c_block_data``; SPI: spidev's
``xfer2``), on hardware or the register-level simulation
(:mod:`~accelcal_ros.driver.register_sim`); everything else is shared. Readings are
returned in g (sensor frame as marked on the chip; the node maps nothing: mount the
sensor with x forward, y left, z up or set ``frame_id`` to its real frame).

Reading strategy: below ``fifo_threshold_hz`` the driver reads the six data registers
once per sample (bypass mode). Above it, a Python loop cannot reliably poll every
sample, so the FIFO runs in stream mode and each poll drains every queued entry (up to
32, i.e. 10 ms at 3200 Hz); the entries get evenly spaced stamps at the measured output
data rate, disciplined to the read time (:class:`FifoTimestamper`). An overrun
(INT_SOURCE.Overrun) means samples were lost; it is counted and reported, never
papered over.
"""
from collections import deque
import errno
import os
import struct
from typing import Any, Deque, Optional, Tuple

from accelcal_ros.driver import adxl345_registers as reg
from accelcal_ros.driver.transport import devid_absent, I2cTransport, Transport
from accelcal_ros.errors import DeviceError, InputError
from accelcal_ros.sensor.datasheet import FULL_RES_G_PER_LSB
import numpy as np

FIFO_WATERMARK = 16
"""FIFO_CTL samples bits: the watermark (entries) that raises the interrupt."""


def open_smbus(bus_number: int) -> object:
    """Open ``/dev/i2c-<bus_number>`` with smbus2; DeviceError with a hint if impossible."""
    path = f'/dev/i2c-{bus_number}'
    if not os.path.exists(path):
        raise DeviceError(f'I2C bus {bus_number}: {path} does not exist (is the I2C interface '
                          'enabled, e.g. dtparam=i2c_arm=on on a Raspberry Pi, and the bus '
                          'number right? see `ls /dev/i2c-*`)')
    try:
        import smbus2
    except ImportError as exc:
        raise DeviceError('the i2c backend needs smbus2 (apt: python3-smbus2, '
                          'pip: smbus2)') from exc
    try:
        return smbus2.SMBus(bus_number)
    except OSError as exc:
        raise DeviceError(f'I2C bus {bus_number}: cannot open {path}: {exc.strerror} '
                          '(permissions? add the user to the i2c group)') from exc


class Adxl345:
    """
    One ADXL345: register map, configuration, sample and FIFO reads, on any transport.

    ``bus`` is a :class:`~accelcal_ros.driver.transport.Transport` (I2C or SPI), or an
    smbus2-like bus, which is wrapped in an :class:`~accelcal_ros.driver.transport.
    I2cTransport` at ``address``.
    """

    def __init__(self, bus: Any, address: int = 0x53, bus_number: Optional[int] = None) -> None:
        if isinstance(bus, Transport):
            self.transport: Transport = bus
        else:
            if address not in reg.VALID_ADDRESSES:
                raise InputError(f'i2c_address 0x{address:02X} is not an ADXL345 address '
                                 f'(0x53 with ALT ADDRESS low, 0x1D with it high)')
            self.transport = I2cTransport(bus, address, bus_number)
        self.address = address
        self.bus_number = bus_number
        self.rate_hz: Optional[float] = None
        self.range_g: Optional[int] = None
        self.fifo = False
        self.watermark = FIFO_WATERMARK

    def _where(self):
        return self.transport.where()

    def check_device_id(self) -> int:
        """Read DEVID; DeviceError naming the bus, the device and the value read unless 0xE5."""
        try:
            value = self.transport.read_register(reg.DEVID)
        except OSError as exc:
            hint = ('no device answered' if exc.errno in (errno.ENXIO, errno.EREMOTEIO)
                    else exc.strerror or str(exc))
            raise DeviceError(f'{self._where()}: cannot read DEVID ({hint}); '
                              f'{self.transport.absent_hint()}') from exc
        if value != reg.DEVID_VALUE:
            if self.transport.kind == 'spi' and devid_absent(value):
                raise DeviceError(f'{self._where()}: DEVID read 0x{value:02X}, expected 0xE5: '
                                  f'{self.transport.absent_hint()}')
            raise DeviceError(f'{self._where()}: DEVID read 0x{value:02X}, expected 0xE5 '
                              '(not an ADXL345, or another device at this address)')
        return value

    def configure(self, rate_hz: float, range_g: int, fifo: bool,
                  watermark_interrupt: bool = False) -> None:
        """
        Set output data rate, range (full resolution), FIFO mode, and start measuring.

        ``watermark_interrupt``: route the FIFO watermark (``watermark`` entries) to INT1,
        active high (INT_MAP bit clear, INT_ENABLE.Watermark), for interrupt-driven reads.
        """
        if float(rate_hz) not in reg.RATE_CODES:
            raise InputError(f'rate_hz {rate_hz} is not an ADXL345 output data rate '
                             f'({", ".join(f"{r:g}" for r in sorted(reg.RATE_CODES))})')
        if range_g not in reg.RANGE_CODES:
            raise InputError(f'range_g {range_g} is not one of 2, 4, 8, 16')
        write = self.transport.write_register
        write(reg.POWER_CTL, 0x00)  # standby while configuring
        write(reg.INT_ENABLE, 0x00)
        write(reg.BW_RATE, reg.RATE_CODES[float(rate_hz)])
        write(reg.DATA_FORMAT, reg.DATA_FORMAT_FULL_RES | reg.RANGE_CODES[range_g])
        write(reg.FIFO_CTL, (reg.FIFO_MODE_STREAM | self.watermark) if fifo
              else reg.FIFO_MODE_BYPASS)
        if watermark_interrupt:
            write(reg.INT_MAP, 0x00)   # every interrupt on INT1
            write(reg.INT_ENABLE, reg.INT_SOURCE_WATERMARK)
        write(reg.POWER_CTL, reg.POWER_CTL_MEASURE)
        self.rate_hz, self.range_g, self.fifo = float(rate_hz), range_g, fifo

    def set_self_test(self, enabled: bool) -> None:
        """Set or clear DATA_FORMAT.SELF_TEST (the electrostatic force on the proof mass)."""
        if self.range_g is None:
            raise InputError('configure the ADXL345 before its self-test')
        value = reg.DATA_FORMAT_FULL_RES | reg.RANGE_CODES[self.range_g]
        self.transport.write_register(
            reg.DATA_FORMAT, value | (reg.DATA_FORMAT_SELF_TEST if enabled else 0))

    def read_counts(self) -> np.ndarray:
        """Read x, y, z as raw LSB counts in one 6-byte transfer (little-endian int16)."""
        data = self.transport.read_block(reg.DATAX0, 6)
        return np.array(struct.unpack('<3h', bytes(data)), dtype=float)

    def read_sample(self) -> np.ndarray:
        """Read x, y, z (g) in one 6-byte block (little-endian int16, 3.9 mg/LSB)."""
        return self.read_counts() * FULL_RES_G_PER_LSB

    def fifo_entries(self) -> int:
        """Return the number of samples waiting in the FIFO (FIFO_STATUS bits 5:0)."""
        return self.transport.read_register(reg.FIFO_STATUS) & reg.FIFO_ENTRIES_MASK

    def overrun(self) -> bool:
        """Return True if the FIFO overran since the last check (INT_SOURCE.Overrun)."""
        return bool(self.transport.read_register(reg.INT_SOURCE) & reg.INT_SOURCE_OVERRUN)

    def read_fifo(self) -> Tuple[np.ndarray, bool]:
        """
        Drain the FIFO: returns ``(samples (N, 3) in g, overrun flag)``.

        Each entry is one 6-byte block read, which pops it (datasheet, FIFO section).
        An I/O error mid-drain raises OSError; entries read before it are not returned, so
        a partly read batch is never published with made-up stamps.
        """
        overrun = self.overrun()
        return self.read_entries(self.fifo_entries()), overrun

    def read_entries(self, count: int) -> np.ndarray:
        """Read ``count`` FIFO entries (``(count, 3)`` in g), one 6-byte transfer each."""
        read = self.transport.read_block
        raw = b''.join([bytes(read(reg.DATAX0, 6)) for _ in range(count)])
        counts = np.frombuffer(raw, dtype='<i2').reshape(count, 3)
        return counts * FULL_RES_G_PER_LSB


class FifoTimestamper:
    """
    Stamps for FIFO batches, evenly spaced and disciplined to the host clock.

    The ADXL345's own oscillator sets its output data rate, which may differ from the
    nominal one by a few percent; stamping at the nominal period then drifts (1 % fast:
    6 s ahead of the host after 10 minutes). Here the period is *measured*: the samples
    read per host second over the last ``window_s`` (once at least ``min_span_s`` is
    covered; clamped to +-``max_rate_error`` of nominal), reported as
    :attr:`measured_rate_hz`. A batch of ``n`` samples read at host time ``t_read``
    continues the previous batch, ``first = last + period``. Its last sample was taken
    at or before ``t_read``, so ``t_read - (n - 1) period`` bounds its first: a stamp
    beyond that bound is pulled back to it at once, and one below it is nudged forward by
    ``gain`` times the offset (the read latency, up to a poll interval, is not a clock
    error: the stamps follow the lower envelope of the read times). An offset beyond
    ``resync_s`` (or two periods; lost samples, a stall) restarts the chain at the host
    time. Stamps stay monotonic (at least half a period apart across batches).
    :meth:`restart` forgets the chain and the rate window (call it after a FIFO overrun);
    the next stamps still follow the last one.
    """

    def __init__(self, rate_hz: float, window_s: float = 10.0, min_span_s: float = 2.0,
                 gain: float = 0.01, resync_s: float = 0.05,
                 max_rate_error: float = 0.1) -> None:
        self.nominal_rate_hz = float(rate_hz)
        self.period = 1.0 / self.nominal_rate_hz
        self.window_s = float(window_s)
        self.min_span_s = float(min_span_s)
        self.gain = float(gain)
        self.resync_s = float(resync_s)
        self.max_rate_error = float(max_rate_error)
        self.last: Optional[float] = None
        self.measured_rate_hz = float('nan')
        self.resyncs = 0
        self._floor = -float('inf')   # stamps after a restart stay after the old chain
        self._reads: Deque[Tuple[float, int]] = deque()   # (t_read, cumulative samples)
        self._total = 0

    def restart(self) -> None:
        """Forget the stamp chain and the rate window (samples were lost); stay monotonic."""
        if self.last is not None:
            self._floor = self.last + 0.5 * self.period
        self.last = None
        self._reads.clear()
        self._total = 0

    def _measure(self, count: int, t_read: float) -> None:
        reads = self._reads
        self._total += count
        reads.append((t_read, self._total))
        while len(reads) > 2 and t_read - reads[1][0] >= self.window_s:
            reads.popleft()
        t0, n0 = reads[0]
        span = t_read - t0
        if span >= self.min_span_s and self._total > n0:
            rate = (self._total - n0) / span
            self.measured_rate_hz = rate
            low = self.nominal_rate_hz * (1.0 - self.max_rate_error)
            high = self.nominal_rate_hz * (1.0 + self.max_rate_error)
            self.period = 1.0 / min(max(rate, low), high)

    def stamps(self, count: int, t_read: float) -> np.ndarray:
        """Return evenly spaced times (s) for ``count`` samples read at ``t_read``."""
        if count == 0:
            return np.empty(0)
        self._measure(count, t_read)
        period = self.period
        host_first = t_read - (count - 1) * period
        if self.last is None:
            first = max(host_first, self._floor)
        else:
            first = self.last + period
            offset = host_first - first
            if offset > max(self.resync_s, 2.0 * period):
                first = host_first
                self.resyncs += 1
            elif offset < 0.0:
                first = host_first
            else:
                first += self.gain * offset
            first = max(first, self.last + 0.5 * period)
        out = first + np.arange(count) * period
        self.last = float(out[-1])
        return out
