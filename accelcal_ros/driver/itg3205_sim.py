"""
A register-map simulator of the ITG-3205 behind the smbus2 interface (pure, for tests).

It answers ``read_byte_data``, ``write_byte_data`` and ``read_i2c_block_data`` as the
chip does (:mod:`accelcal_ros.driver.itg3205`): WHO_AM_I, SMPLRT_DIV, DLPF_FS, INT_CFG,
INT_STATUS (RAW_DATA_RDY, cleared by a data read), TEMP_OUT and GYRO_*OUT (big-endian
int16, 14.375 LSB per deg/s, clipped at +-32767), PWR_MGM (H_RESET restores the
defaults). The rate comes from ``rate_of(t)`` (true angular velocity, rad/s, at the
simulated time ``t`` s) delayed by the configured low-pass's group delay, plus a bias, a
scale error and white noise (the datasheet's 0.38 deg/s rms at 100 Hz bandwidth,
scaled by the square root of the configured bandwidth), drawn from a seeded generator,
at the configured sample rate on an injectable clock. :attr:`who_am_i` can be changed
to imitate another chip, :meth:`fail_next` injects I/O errors (``OSError`` with ``EIO``).
"""
import errno
import math
import time
from typing import Callable, List, Optional, Sequence

from accelcal_ros.driver import itg3205 as reg
import numpy as np


class SimulatedItg3205Bus:
    """smbus2-like bus with one simulated ITG-3205 at ``address``."""

    def __init__(self, rate_of: Callable[[float], Sequence[float]], address: int = 0x68,
                 bias_rad_s: Sequence[float] = (0.0, 0.0, 0.0),
                 scale: Sequence[float] = (1.0, 1.0, 1.0),
                 noise_deg_s: float = reg.NOISE_RMS_DEG_S, temperature_c: float = 30.0,
                 clock: Callable[[], float] = time.monotonic, seed: int = 0) -> None:
        self.rate_of = rate_of
        self.address = address
        self.bias = np.asarray(bias_rad_s, dtype=float).reshape(3)
        self.scale = np.asarray(scale, dtype=float).reshape(3)
        self.noise_rad_s = math.radians(noise_deg_s)
        self.temperature_c = temperature_c
        self.clock = clock
        self.who_am_i = address
        self._rng = np.random.default_rng(seed)
        self._failures = 0
        self._start = clock()
        self._last_sample = -1
        self._latest = (0, 0, 0, 0)
        self.transactions = 0
        self._ready = False
        self._reset()

    def _reset(self) -> None:
        self.registers = {reg.SMPLRT_DIV: 0x00, reg.DLPF_FS: 0x00, reg.INT_CFG: 0x00,
                          reg.PWR_MGM: 0x00}

    def fail_next(self, count: int = 1) -> None:
        """Make the next ``count`` bus transactions raise OSError(EIO)."""
        self._failures += count

    def _transaction(self, address: int) -> None:
        self.transactions += 1
        if self._failures:
            self._failures -= 1
            raise OSError(errno.EIO, 'Remote I/O error (simulated)')
        if address != self.address:
            raise OSError(errno.ENXIO, f'no device at 0x{address:02X}')

    def _sample_rate(self) -> float:
        internal = 8000.0 if self.registers[reg.DLPF_FS] & 0x07 == 0 else 1000.0
        return internal / (self.registers[reg.SMPLRT_DIV] + 1)

    def _update(self) -> bool:
        """Draw the newest sample if one is due; return whether a new one is ready."""
        index = int(math.floor((self.clock() - self._start) * self._sample_rate()))
        if index <= self._last_sample:
            return False
        self._last_sample = index
        t = index / self._sample_rate()
        # the low-pass (DLPF_CFG): its group delay, and the noise of its bandwidth (the
        # datasheet's rms is at 100 Hz)
        code = self.registers[reg.DLPF_FS] & 0x07
        code = code if code in reg.DLPF_DELAY_S else 0
        noise = self.noise_rad_s * math.sqrt(min(reg.DLPF_BANDWIDTHS_HZ[code], 256.0) / 100.0)
        rate = np.asarray(self.rate_of(t - reg.DLPF_DELAY_S[code]), dtype=float) \
            * self.scale + self.bias + self._rng.standard_normal(3) * noise
        counts = np.clip(np.round(np.degrees(rate) * reg.LSB_PER_DEG_S), -32768, 32767)
        temp = int(round((self.temperature_c - 35.0) * 280.0 - 13200))
        self._latest = (temp, int(counts[0]), int(counts[1]), int(counts[2]))
        self._ready = True
        return True

    # -- smbus2 interface -----------------------------------------------------------------
    def read_byte_data(self, address: int, register: int) -> int:
        """Read one register."""
        self._transaction(address)
        if register == reg.WHO_AM_I:
            return self.who_am_i
        if register == reg.INT_STATUS:
            self._update()
            return reg.RAW_DATA_RDY if self._ready else 0
        if register in self.registers:
            return self.registers[register]
        return self._data_bytes()[register - reg.TEMP_OUT_H] \
            if reg.TEMP_OUT_H <= register < reg.TEMP_OUT_H + 8 else 0

    def write_byte_data(self, address: int, register: int, value: int) -> None:
        """Write one register (H_RESET restores the defaults)."""
        self._transaction(address)
        if register == reg.PWR_MGM and value & reg.H_RESET:
            self._reset()
            return
        if register in self.registers:
            self.registers[register] = value & 0xFF

    def read_i2c_block_data(self, address: int, register: int, length: int) -> List[int]:
        """Read ``length`` consecutive registers (the data block clears RAW_DATA_RDY)."""
        self._transaction(address)
        self._update()
        data = self._data_bytes()
        start = register - reg.TEMP_OUT_H
        self._ready = False
        return [data[start + k] if 0 <= start + k < 8 else 0 for k in range(length)]

    def _data_bytes(self) -> List[int]:
        out: List[int] = []
        for value in self._latest:
            raw = value & 0xFFFF
            out += [raw >> 8, raw & 0xFF]
        return out

    def close(self) -> None:
        """Nothing to release (smbus2 interface)."""

    @property
    def latest_counts(self) -> Optional[tuple]:
        """Return the newest ``(temperature, x, y, z)`` counts (for tests)."""
        return self._latest
