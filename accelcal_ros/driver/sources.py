"""
Sample sources behind the driver node: simulated sensor, ADXL345 (I2C or SPI), CSV replay.

Every source has the same polling interface (pure, no ROS):

- ``start()``: open/configure; raises :class:`~accelcal_ros.errors.DeviceError` etc.
- ``next_poll_time()``: wall-clock time (s) at which ``poll()`` should next be called.
- ``poll()``: returns a :class:`Batch` of the samples that became available, stamped in
  wall-clock seconds (``time.time()`` base). A source never invents a sample: an I/O
  error yields an empty batch, counted in :class:`SourceStats`.
- ``stats``: counters for diagnostics.
"""
from dataclasses import dataclass, field
import threading
import time
from typing import Any, Callable, Dict, Optional

from accelcal_ros.driver.adxl345 import Adxl345, FifoTimestamper, open_smbus
from accelcal_ros.driver.adxl345_registers import FIFO_DEPTH
from accelcal_ros.driver.bus_timing import (fifo_poll_period_s, MAX_BUS_LOAD, SAMPLE_BYTES,
                                            STATUS_READS_PER_POLL, transaction_s)
from accelcal_ros.driver.selftest import run_self_test, SelfTestResult
from accelcal_ros.driver.sim_sensor import SimulatedAdxl345
from accelcal_ros.driver.transport import open_spidev, SpiTransport
from accelcal_ros.sensor.recording import load_recording
from accelcal_ros.sensor.units import mps2_to_g
import numpy as np


@dataclass
class Batch:
    """Samples in g with wall-clock stamps; ``truth_rp`` (rad) only from the simulator."""

    stamps: np.ndarray
    samples_g: np.ndarray
    truth_rp: Optional[np.ndarray] = None

    @classmethod
    def empty(cls) -> 'Batch':
        """Return a batch without samples."""
        return cls(np.empty(0), np.empty((0, 3)))

    def __len__(self):
        """Return the number of samples."""
        return len(self.stamps)


@dataclass
class SourceStats:
    """Counters reported in diagnostics."""

    samples: int = 0
    io_errors: int = 0
    consecutive_errors: int = 0
    fifo_overruns: int = 0
    last_error: str = ''
    finished: bool = False
    measured_rate_hz: float = float('nan')
    """The sensor's output data rate measured from FIFO sample counts (Hz; NaN if none)."""
    stamp_resyncs: int = 0
    extra: dict = field(default_factory=dict)


class SimSource:
    """
    Samples of a :class:`~accelcal_ros.driver.sim_sensor.SimulatedAdxl345` in real time.

    Sample ``k`` is due at ``t0 + k / rate`` and carries the simulator's state at
    ``k / rate`` seconds of simulated time. ``max_batch_period_s`` groups samples at high
    rates (at 3200 Hz a poll every 1.25 ms publishes four samples).
    """

    def __init__(self, sensor: SimulatedAdxl345, clock: Callable[[], float] = time.time,
                 max_batch_period_s: float = 0.001) -> None:
        self.sensor = sensor
        self.clock = clock
        self.period = 1.0 / sensor.rate_hz
        # samples per poll: 1 up to 1 kHz, then groups spanning about max_batch_period_s
        self.batch = max(1, int(np.ceil(max_batch_period_s / self.period - 1e-9)))
        self.stats = SourceStats()
        self._t0 = 0.0   # set by start()
        self._next = 0

    def start(self) -> None:
        """Start the simulated clock now."""
        self._t0 = self.clock()
        self._next = 0

    def next_poll_time(self) -> float:
        """
        Return when the next sample (or group of samples) is due.

        Poll times lie on the sample grid (``t0 + k / rate``), so a late wake-up never
        delays the following polls.
        """
        return self._t0 + (self._next + self.batch - 1) * self.period

    def poll(self) -> 'Batch':
        """Return every sample due by now."""
        due = int(np.floor((self.clock() - self._t0) / self.period + 1e-9)) + 1
        if due <= self._next:
            return Batch.empty()
        sim_t = np.arange(self._next, due) * self.period
        self._next = due
        samples, roll, pitch = self.sensor.read_with_truth(sim_t)
        self.stats.samples += len(sim_t)
        return Batch(self._t0 + sim_t, samples, np.stack([roll, pitch], axis=1))


class Adxl345Source:
    """
    An ADXL345 on I2C or SPI, read per sample (bypass) or by draining the FIFO (stream).

    The transport (:mod:`~accelcal_ros.driver.transport`) is the only difference between
    the buses; the reads, the error handling and the stamps are this class's. On an I/O
    error the source backs off exponentially (``min_backoff_s`` doubling up to
    ``max_backoff_s``), counts the error and returns nothing for that poll; it never
    fabricates a sample. FIFO overruns (samples lost while the bus was unavailable or the
    host too slow) are counted, and the samples lost estimated from the time between reads.

    ``interrupt``: an object with ``wait_edge(timeout_s) -> Optional[float]`` (the FIFO
    watermark on INT1, the edge's time on ``clock``'s base, or None on a time-out). Each
    poll then waits for the edge, and the batch's stamps are disciplined to the edge time
    (the watermark-th sample was taken then) instead of the read time.
    """

    def __init__(self, device: Adxl345, rate_hz: float, range_g: int, use_fifo: bool,
                 clock: Callable[[], float] = time.time, min_backoff_s: float = 0.002,
                 max_backoff_s: float = 0.5, bus_speed_hz: Optional[float] = None,
                 interrupt: Any = None) -> None:
        self.device = device
        self.rate_hz = float(rate_hz)
        self.range_g = range_g
        self.use_fifo = use_fifo or interrupt is not None
        self.clock = clock
        self.min_backoff_s = min_backoff_s
        self.max_backoff_s = max_backoff_s
        self.bus_speed_hz = bus_speed_hz
        self.interrupt = interrupt
        self.period = 1.0 / self.rate_hz
        self.poll_period = fifo_poll_period_s(self.rate_hz) if self.use_fifo else self.period
        self.stats = SourceStats()
        self.lost_samples = 0
        self.interrupt_timeouts = 0
        self.overruns_host = 0
        self.lost_host = 0
        self.overruns_bus = 0
        self.sim_chip: Any = None
        self.rate_warning = ''
        self.lock = threading.Lock()
        self._stamper = FifoTimestamper(self.rate_hz)
        self._next_poll = 0.0   # set by start()
        self._last_read: Optional[float] = None
        self._last_start = self._start_before = 0.0
        self._count_before = 0
        self._last_count = 0
        self._last_overrun_host: Optional[bool] = None
        self._pending_lost = 0
        self._backoff = 0.0

    @classmethod
    def from_bus_number(cls, bus_number: int, address: int, rate_hz: float, range_g: int,
                        use_fifo: bool, **kwargs: Any) -> 'Adxl345Source':
        """Open ``/dev/i2c-<bus_number>`` and wrap the ADXL345 at ``address``."""
        bus = open_smbus(bus_number)
        return cls(Adxl345(bus, address, bus_number), rate_hz, range_g, use_fifo, **kwargs)

    @classmethod
    def from_spi(cls, bus_number: int, chip_select: int, speed_hz: float, rate_hz: float,
                 range_g: int, use_fifo: bool, **kwargs: Any) -> 'Adxl345Source':
        """Open ``/dev/spidev<bus>.<cs>`` (mode 3, ``speed_hz``) and wrap the ADXL345 on it."""
        spi = open_spidev(bus_number, chip_select, speed_hz)
        device = Adxl345(SpiTransport(spi, bus_number, chip_select))
        return cls(device, rate_hz, range_g, use_fifo, bus_speed_hz=speed_hz, **kwargs)

    @property
    def bus(self) -> str:
        """``i2c`` or ``spi``."""
        return self.device.transport.kind

    def start(self) -> None:
        """Check DEVID and configure the device (DeviceError if it is not an ADXL345)."""
        with self.lock:
            self.device.check_device_id()
            self.device.configure(self.rate_hz, self.range_g, self.use_fifo,
                                  watermark_interrupt=self.interrupt is not None)
            self._stamper.restart()
            self._last_read = self._last_start = self.clock()   # the FIFO fills from now on
            self._start_before, self._last_count, self._count_before = self._last_start, 0, 0
            self._next_poll = self._last_read + self.period

    def next_poll_time(self) -> float:
        """Return when to poll next (later while backing off after errors)."""
        return self._next_poll

    def _wait_edge(self):
        """Return the interrupt's edge time, or None (time-out: drain anyway, as polling)."""
        edge = self.interrupt.wait_edge(max(4 * self.device.watermark * self.period, 0.05))
        if edge is None:
            self.interrupt_timeouts += 1
        return edge

    def poll(self) -> 'Batch':
        """Read what is available; an I/O error gives an empty batch and a back-off."""
        edge = self._wait_edge() if self.interrupt is not None else None
        with self.lock:
            return self._poll(edge)

    def _poll(self, edge):
        now = self.clock()
        try:
            if self.use_fifo:   # as Adxl345.read_fifo, with the time of FIFO_STATUS
                overrun = self.device.overrun()
                count = self.device.fifo_entries()
                t_status = self.clock()
                samples = self.device.read_entries(count)
                if overrun:
                    self.stats.fifo_overruns += 1
                    self._stamper.restart()  # samples were lost: restart the stamp chain
            else:
                samples, overrun = self.device.read_sample()[None, :], False
                t_status = now
        except OSError as exc:
            self.stats.io_errors += 1
            self.stats.consecutive_errors += 1
            self.stats.last_error = f'{exc.strerror or exc} (errno {exc.errno})'
            self._backoff = min(max(2 * self._backoff, self.min_backoff_s), self.max_backoff_s)
            self._next_poll = now + self._backoff
            self._last_read = None
            return Batch.empty()
        self._backoff = 0.0
        self.stats.consecutive_errors = 0
        t_read = self.clock()
        if self.use_fifo and self._last_read is not None:
            self._count_loss(t_status, len(samples), overrun)
        if overrun and self._last_read is not None:
            self._last_overrun_host = self._attribute_loss(t_status, t_read, len(samples))
        else:
            self._last_overrun_host = None
        self._start_before, self._count_before = self._last_start, self._last_count
        self._last_read, self._last_start, self._last_count = t_read, t_status, len(samples)
        if self.use_fifo:
            t_last = t_read
            # the edge dates the watermark sample only if nothing was lost since: after an
            # overrun the FIFO holds the newest samples, the last one taken by t_read
            if edge is not None and not overrun and len(samples) >= self.device.watermark:
                t_last = min(t_read, edge + (len(samples) - self.device.watermark) * self.period)
            stamps = self._stamper.stamps(len(samples), t_last)
            self.stats.measured_rate_hz = self._stamper.measured_rate_hz
            self.stats.stamp_resyncs = self._stamper.resyncs
        else:
            stamps = np.array([t_read])
        self.stats.samples += len(samples)
        self._next_poll = now if self.interrupt is not None \
            else max(self._next_poll + self.poll_period, now)
        return Batch(stamps, samples)

    def _count_loss(self, t_status, count, flagged):
        """
        Count the samples lost since the previous drain's FIFO_STATUS read.

        Between the previous FIFO_STATUS read and this one, ``(t - t_prev) x rate``
        samples arrived; the previous drain popped what was there then, so the FIFO should
        now hold all arrivals: what it lacks, the overflow dropped. Only a full FIFO can
        have lost any; the overrun flag may come a drain late (the FIFO overflowed after
        this drain's INT_SOURCE read, while the host stalled before FIFO_STATUS), so a full
        FIFO is judged whether or not the flag is set (unflagged: beyond one sample of
        clock rounding). The loss waits in ``_pending_lost`` for the overrun's blame.
        """
        if not flagged and count < FIFO_DEPTH - 1:
            return
        lost = max(0, int(round((t_status - self._last_start) * self.rate_hz)) - count)
        if not flagged and lost < 2:
            return
        self.lost_samples += lost
        self._pending_lost += lost

    def _attribute_loss(self, t_status, t_read, count):
        """
        Blame the host or the bus for an overrun, with the samples it lost.

        INT_SOURCE (read first in each drain) reports an overflow that happened since the
        previous drain's status reads (or, when that drain found the FIFO full, since the
        one before). Over that time the drains' reads (entries and status reads) took
        their wire time (:mod:`bus_timing`). A bus busy for at least ``MAX_BUS_LOAD`` of it
        was too slow for the rate (at 3200 Hz on I2C at 100 kHz: 90 %); otherwise the
        host's own time (not scheduled, Python, system calls) let the FIFO fill up (SPI at
        5 MHz: 5 %). Consecutive overrunning drains are one event with one blame.
        """
        lost, self._pending_lost = self._pending_lost, 0   # counted by _count_loss
        start, entries, drains = self._last_start, self._last_count + count, 2
        if self._last_count >= FIFO_DEPTH - 1:
            # the previous drain found the FIFO full: it overflowed after that drain's
            # status reads, before its first pop; judge the time that filled it
            start, entries, drains = self._start_before, entries + self._count_before, 3
        wire = 0.0
        if self.bus_speed_hz:
            wire = (entries * transaction_s(self.bus, self.bus_speed_hz, SAMPLE_BYTES,
                                            pops_fifo=True)
                    + drains * STATUS_READS_PER_POLL
                    * transaction_s(self.bus, self.bus_speed_hz, 1))
        # the FIFO fills from empty in FIFO_DEPTH sample periods: a judged span shorter
        # than that cannot hold the overflow, which then happened while the host did not
        # run the driver (before the span: a stall between two reads of a drain)
        span = t_read - start
        host = span < FIFO_DEPTH / self.rate_hz or wire < MAX_BUS_LOAD * span
        if self._last_overrun_host is not None:
            # the previous drain found the FIFO overflowing too (it overflows again between
            # its INT_SOURCE read and its first pop): the same event, the same blame
            host = self._last_overrun_host
        elif host:
            self.overruns_host += 1
        else:
            self.overruns_bus += 1
        if host:
            self.lost_host += lost
        return host

    def diagnostic_values(self) -> Dict[str, str]:
        """Bus, clock and loss figures for ``/diagnostics``."""
        values = {'bus': self.bus, 'fifo_lost_samples_estimated': str(self.lost_samples),
                  'interrupt_timeouts': str(self.interrupt_timeouts),
                  'fifo_overruns_host_stall': str(self.overruns_host),
                  'fifo_lost_samples_host_stall': str(self.lost_host),
                  'fifo_overruns_bus_too_slow': str(self.overruns_bus),
                  'reads': 'interrupt (INT1 watermark)' if self.interrupt is not None
                  else 'polling'}
        if self.bus_speed_hz:
            values['bus_speed_hz'] = f'{self.bus_speed_hz:g}'
        chip = self.sim_chip
        if chip is not None:   # the simulation's truth: what the chip's FIFO dropped
            values['sim_fifo_dropped_samples'] = str(chip.dropped)
            values['sim_samples_generated'] = str(chip.generated)
            values['sim_bus_busy_s'] = f'{chip.busy_s:.3f}'
        return values

    def self_test(self, supply_voltage_v: float, **kwargs: Any) -> 'SelfTestResult':
        """Run the datasheet self-test (streaming pauses), then resume streaming."""
        with self.lock:
            try:
                return run_self_test(self.device, supply_voltage_v, **kwargs)
            finally:
                self.device.configure(self.rate_hz, self.range_g, self.use_fifo,
                                      watermark_interrupt=self.interrupt is not None)
                self._stamper.restart()
                self._last_read = None


I2cSource = Adxl345Source
"""The ADXL345 source (the name from the I2C-only driver; SPI uses the same class)."""


class ReplaySource:
    """
    A recording (``t,ax,ay,az``; s, m/s^2) replayed with its timing or at full speed.

    Stamps keep the recorded spacing, shifted to start at the replay's start time.
    """

    def __init__(self, path: str, realtime: bool = True,
                 clock: Callable[[], float] = time.time, chunk: int = 500) -> None:
        self.t, accel = load_recording(path)
        self.samples_g = mps2_to_g(accel)
        self.realtime = realtime
        self.clock = clock
        self.chunk = chunk
        self.stats = SourceStats()
        self._t0 = 0.0   # set by start()
        self._next = 0

    def start(self) -> None:
        """Start replaying now."""
        self._t0 = self.clock()
        self._next = 0

    def next_poll_time(self) -> float:
        """Return when the next recorded sample is due (now when not in real time)."""
        if self._next >= len(self.t):
            return self.clock() + 0.1
        if not self.realtime:
            return self.clock()
        return self._t0 + (self.t[self._next] - self.t[0])

    def poll(self) -> 'Batch':
        """Return the next recorded samples that are due."""
        if self._next >= len(self.t):
            self.stats.finished = True
            return Batch.empty()
        if self.realtime:
            elapsed = self.clock() - self._t0
            end = int(np.searchsorted(self.t - self.t[0], elapsed, side='right'))
        else:
            end = min(self._next + self.chunk, len(self.t))
        start, self._next = self._next, max(end, self._next)
        if self._next >= len(self.t):
            self.stats.finished = True
        self.stats.samples += self._next - start
        return Batch(self._t0 + self.t[start:self._next] - self.t[0],
                     self.samples_g[start:self._next])
