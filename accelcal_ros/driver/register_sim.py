"""
A register-level simulation of the ADXL345 on I2C (smbus2's interface) or SPI (spidev's).

The chip answers like the real one: DEVID, BW_RATE, DATA_FORMAT (range, FULL_RES,
SELF_TEST), POWER_CTL (measure), INT_ENABLE/INT_MAP, FIFO_CTL (bypass/stream,
watermark), FIFO_STATUS, INT_SOURCE (overrun, watermark, data ready) and the data
registers (little-endian int16, right-justified). Samples come from a physical source
(e.g. :class:`~accelcal_ros.driver.sim_sensor.SimulatedAdxl345`) at the configured output
data rate on an injectable clock. In stream mode a 32-entry FIFO keeps the newest samples,
sets Overrun when one is dropped and counts the dropped ones (:attr:`dropped`, the
truth the driver's diagnostics are checked against). With SELF_TEST set, the
electrostatic self-test force shifts each axis by :attr:`self_test_shift_g` (a healthy
sensor by default; set an axis to 0 for a broken one).

Bus time: with ``bus_speed_hz`` every transaction costs its time on the wire
(:mod:`~accelcal_ros.driver.bus_timing`): the bus is busy until the transaction ends,
the chip never shows samples from after the caller's clock, and the caller is held
(``sleep``, in steps of at most ``max_lag_s``) until the wire time has passed, so the
driver on the simulation achieves what it would on a real bus. Without it, transactions
take no time (today's unit tests).

:meth:`fail_next` injects I/O errors (``OSError`` with ``EIO``), :attr:`devid` imitates
another chip (0x00 or 0xFF: nothing on SPI). The watermark line (INT1) is modelled by
:meth:`int1_level` and :meth:`wait_int1`.
"""
from collections import deque
import errno
import threading
import time
from typing import Any, Callable, Deque, List, Optional, Sequence

from accelcal_ros.driver import adxl345_registers as reg
from accelcal_ros.driver import bus_timing
from accelcal_ros.sensor.datasheet import FULL_RES_G_PER_LSB
import numpy as np

_RATES = {code: rate for rate, code in reg.RATE_CODES.items()}
HEALTHY_SELF_TEST_SHIFT_G = (0.8, -0.8, 1.2)
"""Self-test output change (g) of the simulated sensor at VS = 2.5 V (inside Table 15)."""
_BLOCK = 64
"""Samples computed ahead at once (the physical source is vectorised)."""


class SimulatedAdxl345Bus:
    """smbus2-like bus with one simulated ADXL345 at ``address``."""

    bus_kind = 'i2c'

    def __init__(self, source: Any, address: int = 0x53,
                 clock: Callable[[], float] = time.monotonic,
                 devid: int = reg.DEVID_VALUE, bus_speed_hz: Optional[float] = None,
                 sleep: Callable[[float], None] = time.sleep, max_lag_s: float = 0.0005,
                 self_test_shift_g: Sequence[float] = HEALTHY_SELF_TEST_SHIFT_G,
                 self_test_scale: Any = (1.0, 1.0, 1.0)) -> None:
        self.source = source
        self.address = address
        self.clock = clock
        self.devid = devid
        self.bus_speed_hz = bus_speed_hz
        self.sleep = sleep
        self.max_lag_s = max_lag_s
        self.self_test_shift_g = np.asarray(self_test_shift_g, dtype=float) \
            * np.asarray(self_test_scale, dtype=float)
        self.registers = {reg.BW_RATE: 0x0A, reg.DATA_FORMAT: 0x00, reg.POWER_CTL: 0x00,
                          reg.FIFO_CTL: 0x00, reg.INT_ENABLE: 0x00, reg.INT_MAP: 0x00}
        self.fifo: Deque[bytes] = deque(maxlen=reg.FIFO_DEPTH)
        self.latest = bytes(6)
        self.overrun = False
        self.generated = 0
        self.dropped = 0
        self.busy_s = 0.0
        self._bus_free = 0.0
        self._start: Optional[float] = None
        self._failures = 0
        self._ahead = np.empty((0, 3))
        self._ahead_from = 0
        self._edge = threading.Condition()
        self._now = 0.0
        self._watermark_at = 0.0
        self.transactions = 0

    # -- test controls -------------------------------------------------------------
    def fail_next(self, count: int = 1) -> None:
        """Make the next ``count`` bus transactions raise OSError(EIO)."""
        self._failures += count

    # -- simulated chip --------------------------------------------------------------
    def _rate(self):
        return _RATES.get(self.registers[reg.BW_RATE] & 0x0F, 100.0)

    def _measuring(self):
        return bool(self.registers[reg.POWER_CTL] & reg.POWER_CTL_MEASURE)

    def _stream(self):
        return (self.registers[reg.FIFO_CTL] & 0xC0) == reg.FIFO_MODE_STREAM

    def _values(self, first, last):
        """Physical samples ``first .. last - 1`` (g), computed ahead in blocks."""
        end = self._ahead_from + len(self._ahead)
        if first < self._ahead_from or last > end:
            count = max(last - first, _BLOCK)
            times = (np.arange(first, first + count) + 1) / self._rate()
            self._ahead = np.atleast_2d(self.source.read(times))
            self._ahead_from = first
        return self._ahead[first - self._ahead_from:last - self._ahead_from]

    def _advance(self, now=None):
        """Generate every sample due by ``now`` (default: the clock) at the output data rate."""
        if not self._measuring():
            return
        now = self.clock() if now is None else now
        due = int((now - self._start) * self._rate() + 1e-9)
        if due <= self.generated:
            return
        values = self._values(self.generated, due)
        self.generated = due
        if self.registers[reg.DATA_FORMAT] & reg.DATA_FORMAT_SELF_TEST:
            values = values + self.self_test_shift_g
        raw = self._encode(values[-reg.FIFO_DEPTH:])
        entries = [raw[k:k + 6] for k in range(0, len(raw), 6)]
        if self._stream():
            first, before = due - len(values), len(self.fifo)
            mark = self.registers[reg.FIFO_CTL] & 0x1F
            if before < mark <= before + len(values):   # the sample that reached it
                self._watermark_at = self._start + (first + mark - before) / self._rate()
            free = reg.FIFO_DEPTH - len(self.fifo)
            if len(values) > free:
                self.overrun = True
                self.dropped += len(values) - free
            self.fifo.extend(entries)
        self.latest = entries[-1]
        if self._watermark():
            with self._edge:
                self._edge.notify_all()

    def _encode(self, values):
        """Return samples ``(N, 3)`` in g as the data registers hold them: ``N * 6`` bytes."""
        range_g = 2 ** ((self.registers[reg.DATA_FORMAT] & 0x03) + 1)
        lsb = FULL_RES_G_PER_LSB
        if not self.registers[reg.DATA_FORMAT] & reg.DATA_FORMAT_FULL_RES:
            lsb = FULL_RES_G_PER_LSB * range_g / 2.0  # 10-bit mode
        limit = int(round(range_g / lsb))
        counts = np.clip(np.round(np.asarray(values) / lsb), -limit, limit - 1)
        return counts.astype('<i2').tobytes()

    def _watermark(self):
        return self._stream() and len(self.fifo) >= (self.registers[reg.FIFO_CTL] & 0x1F)

    def _charge(self, data_bytes, write=False, pops_fifo=False):
        """Occupy the bus for the transaction's wire time; return the time the chip sees."""
        now = self.clock()
        if self.bus_speed_hz is None:
            return now
        seconds = bus_timing.transaction_s(self.bus_kind, self.bus_speed_hz, data_bytes,
                                           write, pops_fifo)
        start = max(now, self._bus_free)
        self._bus_free = start + seconds
        self.busy_s += seconds
        lag = self._bus_free - now
        if lag > self.max_lag_s:
            self.sleep(lag)
            return self.clock()
        # the caller returns before the wire time has all passed (it catches up at the
        # next sleep): the chip must not show it samples from after its own clock
        return now

    def _transaction(self, address, data_bytes=1, write=False, pops_fifo=False):
        self.transactions += 1
        if self._failures:
            self._failures -= 1
            raise OSError(errno.EIO, 'Input/output error (injected)')
        if address != self.address:
            raise OSError(errno.ENXIO, 'No such device or address')
        self._now = self._charge(data_bytes, write, pops_fifo)
        self._advance(self._now)

    def _read_register(self, register):
        if register == reg.DEVID:
            return self.devid
        if register == reg.FIFO_STATUS:
            return min(len(self.fifo), reg.FIFO_DEPTH) & reg.FIFO_ENTRIES_MASK
        if register == reg.INT_SOURCE:
            value = (reg.INT_SOURCE_OVERRUN if self.overrun else 0) | reg.INT_SOURCE_DATA_READY
            value |= reg.INT_SOURCE_WATERMARK if self._watermark() else 0
            self.overrun = False  # cleared by reading, as on the chip (once data is read)
            return value
        return self.registers.get(register, 0)

    def _write_register(self, register, value):
        self.registers[register] = value & 0xFF
        if register == reg.FIFO_CTL and not self._stream():
            self.fifo.clear()
        if register == reg.POWER_CTL:
            self._start = self._now if self._measuring() else None
            self.generated = 0
            self._ahead = np.empty((0, 3))
            self._ahead_from = 0
            self.fifo.clear()

    def _read_data(self):
        """Return the 6 data bytes; with the FIFO in stream mode this pops one entry."""
        if self._stream() and self.fifo:
            return list(self.fifo.popleft())
        return list(self.latest)

    # -- INT1 (watermark) -------------------------------------------------------------
    def int1_level(self) -> bool:
        """Level of INT1: high while the watermark interrupt is enabled and pending."""
        self._advance()
        return bool(self.registers[reg.INT_ENABLE] & reg.INT_SOURCE_WATERMARK) \
            and self._watermark()

    def watermark_time(self) -> float:
        """Return when (on the chip's clock) the FIFO last reached the watermark."""
        return self._watermark_at

    def wait_int1(self, timeout_s: float) -> bool:
        """Block until INT1 is high or ``timeout_s`` passed (the simulated GPIO edge)."""
        deadline = self.clock() + timeout_s
        while not self.int1_level():
            # the chip makes samples only when looked at: look again at the next sample
            step = min(1.0 / self._rate(), deadline - self.clock())
            if step <= 0:
                return False
            with self._edge:
                self._edge.wait(step)
        return True

    # -- smbus2 interface ------------------------------------------------------------
    def read_byte_data(self, address: int, register: int) -> int:
        """Read one register."""
        self._transaction(address)
        return self._read_register(register)

    def write_byte_data(self, address: int, register: int, value: int) -> None:
        """Write one register; leaving stream mode clears the FIFO."""
        self._transaction(address, write=True)
        self._write_register(register, value)

    def read_i2c_block_data(self, address: int, register: int, length: int) -> List[int]:
        """Multi-byte read; from DATAX0 with the FIFO on it pops one entry."""
        data_read = register == reg.DATAX0 and length == 6
        self._transaction(address, length, pops_fifo=data_read and self._stream())
        if not data_read:
            return [self._read_register(register + k) for k in range(length)]
        return self._read_data()

    def close(self) -> None:
        """Nothing to release."""


class SimulatedAdxl345Spi(SimulatedAdxl345Bus):
    """
    spidev-like device (``xfer2``, ``mode``, ``max_speed_hz``) with one simulated ADXL345.

    The command byte's bit 7 reads, bit 6 (MB) increments the address over a multi-byte
    transfer (without it the chip repeats the same register), bits 5:0 address. A mode
    other than 3 samples on the wrong edge: every byte comes back shifted by one bit.
    ``bus_speed_hz`` follows ``max_speed_hz`` when the driver sets it.
    """

    bus_kind = 'spi'

    def __init__(self, source: Any, **kwargs: Any) -> None:
        super().__init__(source, address=0, **kwargs)
        self.mode = 0
        self.bits_per_word = 8

    @property
    def max_speed_hz(self) -> int:
        """SPI clock (Hz) the wire time is charged at."""
        return int(self.bus_speed_hz or 0)

    @max_speed_hz.setter
    def max_speed_hz(self, value: int) -> None:
        self.bus_speed_hz = float(value)

    def xfer2(self, values: Sequence[int]) -> List[int]:
        """One transfer with chip select held low: command byte, then data."""
        command, data = values[0], list(values[1:])
        read, multi, register = command & 0x80, command & 0x40, command & 0x3F
        data_read = bool(read) and register == reg.DATAX0 and len(data) == 6 and bool(multi)
        self._transaction(0, len(data), write=not read,
                          pops_fifo=data_read and self._stream())
        if not read:
            for k, value in enumerate(data):
                self._write_register(register + (k if multi else 0), value)
            return [0] * len(values)
        if data_read:
            reply = self._read_data()
        else:
            reply = [self._read_register(register + (k if multi else 0))
                     for k in range(len(data))]
        if self.mode != 3:
            reply = [(b >> 1) | 0x80 for b in reply]
        return [0xFF] + reply
