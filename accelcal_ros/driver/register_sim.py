"""
A register-map simulator of the ADXL345 behind the smbus2 interface, for tests.

It answers ``read_byte_data``, ``write_byte_data`` and ``read_i2c_block_data`` like the
chip: DEVID, BW_RATE, DATA_FORMAT (range, FULL_RES), POWER_CTL (measure), FIFO_CTL
(bypass/stream), FIFO_STATUS, INT_SOURCE (overrun, data ready) and the data registers
(little-endian int16, right-justified). Samples come from a physical source (e.g.
:class:`~accelcal_ros.driver.sim_sensor.SimulatedAdxl345`) at the configured output data
rate on an injectable clock. In stream mode a 32-entry FIFO keeps the newest samples and
sets Overrun when one is dropped. :meth:`fail_next` injects I/O errors (``OSError``
with ``EIO``), :attr:`devid` can be changed to imitate a different chip.
"""
from collections import deque
import errno
import struct
import time
from typing import Any, Callable, Deque, List, Optional

from accelcal_ros.driver import adxl345_registers as reg
from accelcal_ros.sensor.datasheet import FULL_RES_G_PER_LSB
import numpy as np

_RATES = {code: rate for rate, code in reg.RATE_CODES.items()}


class SimulatedAdxl345Bus:
    """smbus2-like bus with one simulated ADXL345 at ``address``."""

    def __init__(self, source: Any, address: int = 0x53,
                 clock: Callable[[], float] = time.monotonic,
                 devid: int = reg.DEVID_VALUE) -> None:
        self.source = source
        self.address = address
        self.clock = clock
        self.devid = devid
        self.registers = {reg.BW_RATE: 0x0A, reg.DATA_FORMAT: 0x00, reg.POWER_CTL: 0x00,
                          reg.FIFO_CTL: 0x00}
        self.fifo: Deque[np.ndarray] = deque(maxlen=reg.FIFO_DEPTH)
        self.latest = np.zeros(3)
        self.overrun = False
        self.generated = 0
        self._start: Optional[float] = None
        self._failures = 0
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

    def _advance(self):
        """Generate every sample due by now at the output data rate."""
        if not self._measuring():
            return
        now = self.clock()
        due = int((now - self._start) * self._rate() + 1e-9)
        if due <= self.generated:
            return
        times = (np.arange(self.generated, due) + 1) / self._rate()
        self.generated = due
        values = np.atleast_2d(self.source.read(times))
        for value in values:
            if self._stream():
                if len(self.fifo) == reg.FIFO_DEPTH:
                    self.overrun = True
                self.fifo.append(value)
            self.latest = value

    def _encode(self, value):
        range_g = 2 ** ((self.registers[reg.DATA_FORMAT] & 0x03) + 1)
        lsb = FULL_RES_G_PER_LSB
        if not self.registers[reg.DATA_FORMAT] & reg.DATA_FORMAT_FULL_RES:
            lsb = FULL_RES_G_PER_LSB * range_g / 2.0  # 10-bit mode
        limit = int(round(range_g / lsb))
        counts = np.clip(np.round(np.asarray(value) / lsb), -limit, limit - 1).astype(int)
        return list(struct.pack('<3h', *counts))

    def _transaction(self, address):
        self.transactions += 1
        if self._failures:
            self._failures -= 1
            raise OSError(errno.EIO, 'Input/output error (injected)')
        if address != self.address:
            raise OSError(errno.ENXIO, 'No such device or address')
        self._advance()

    # -- smbus2 interface ------------------------------------------------------------
    def read_byte_data(self, address: int, register: int) -> int:
        """Read one register."""
        self._transaction(address)
        if register == reg.DEVID:
            return self.devid
        if register == reg.FIFO_STATUS:
            return min(len(self.fifo), reg.FIFO_DEPTH) & reg.FIFO_ENTRIES_MASK
        if register == reg.INT_SOURCE:
            value = (reg.INT_SOURCE_OVERRUN if self.overrun else 0) | reg.INT_SOURCE_DATA_READY
            self.overrun = False  # cleared by reading, as on the chip (once data is read)
            return value
        return self.registers.get(register, 0)

    def write_byte_data(self, address: int, register: int, value: int) -> None:
        """Write one register; leaving stream mode clears the FIFO."""
        self._transaction(address)
        self.registers[register] = value & 0xFF
        if register == reg.FIFO_CTL and not self._stream():
            self.fifo.clear()
        if register == reg.POWER_CTL:
            self._start = self.clock() if self._measuring() else None
            self.generated = 0

    def read_i2c_block_data(self, address: int, register: int, length: int) -> List[int]:
        """Multi-byte read; from DATAX0 with the FIFO on it pops one entry."""
        self._transaction(address)
        if register != reg.DATAX0 or length != 6:
            return [self.read_byte_data(address, register + k) for k in range(length)]
        if self._stream():
            value = self.fifo.popleft() if self.fifo else self.latest
        else:
            value = self.latest
        return self._encode(value)

    def close(self) -> None:
        """Nothing to release."""
