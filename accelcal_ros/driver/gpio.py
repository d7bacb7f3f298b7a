"""
The ADXL345's INT1 line (FIFO watermark) as an interrupt: libgpiod, or the simulation's line.

Pure (no ROS). Both classes offer ``wait_edge(timeout_s) -> Optional[float]``: the time of
the rising edge on the wall clock (``time.time()`` base, the stamps' base), or None when no
edge came in ``timeout_s`` (the source then drains anyway: polling as the fallback). A
line that is already high (the FIFO still above the watermark after a drain) counts as an
edge now: a level that never falls would give no new edge.

- :class:`GpiodInterrupt`: libgpiod's Python bindings (``gpiod`` >= 2, PyPI; Debian
  ``python3-libgpiod``), rising-edge detection on ``/dev/gpiochipN`` line ``offset``; the
  kernel stamps each edge (CLOCK_MONOTONIC), converted here to the wall clock.
- :class:`SimulatedInterrupt`: the register-level simulation's INT1
  (:meth:`~accelcal_ros.driver.register_sim.SimulatedAdxl345Bus.wait_int1`), edge time =
  when the watermark-th sample entered the FIFO.
"""
import os
import time
from typing import Any, Optional

from accelcal_ros.errors import DeviceError


def _monotonic_to_wall(t_monotonic: float) -> float:
    """Convert a CLOCK_MONOTONIC time (s) to the wall clock."""
    return time.time() - (time.monotonic() - t_monotonic)


class GpiodInterrupt:
    """Rising edges of line ``offset`` of ``/dev/<chip>`` through libgpiod."""

    def __init__(self, chip: str, offset: int) -> None:
        path = chip if chip.startswith('/') else f'/dev/{chip}'
        if not os.path.exists(path):
            raise DeviceError(f'GPIO chip {path} does not exist (see `ls /dev/gpiochip*` or '
                              '`gpiodetect`; set int1_gpio_chip)')
        try:
            import gpiod
            from gpiod.line import Edge
        except ImportError as exc:
            raise DeviceError("interrupt reads need libgpiod's Python bindings (pip: gpiod, "
                              'apt: python3-libgpiod)') from exc
        try:
            with gpiod.Chip(path) as handle:
                lines = handle.get_info().num_lines
        except OSError as exc:
            raise DeviceError(f'GPIO chip {path}: cannot open it: {exc.strerror or exc} '
                              '(permissions? add the user to the gpio group)') from exc
        if not 0 <= offset < lines:
            raise DeviceError(f'GPIO line {offset} does not exist on {path} (it has lines '
                              f'0..{lines - 1}; see `gpioinfo`; set int1_gpio_line)')
        try:
            self._request = gpiod.request_lines(
                path, consumer='accelcal imu_driver INT1',
                config={offset: gpiod.LineSettings(edge_detection=Edge.RISING)})
        except OSError as exc:
            raise DeviceError(f'GPIO line {offset} on {path}: cannot request it: '
                              f'{exc.strerror or exc} (in use by another program?)') from exc
        self._offset = offset
        self._active = gpiod.line.Value.ACTIVE

    def wait_edge(self, timeout_s: float) -> Optional[float]:
        """Return the wall-clock time of the next rising edge, or None after ``timeout_s``."""
        if self._request.get_value(self._offset) == self._active:
            if self._request.wait_edge_events(0):
                self._request.read_edge_events()   # an old edge: this level is newer
            return time.time()
        if not self._request.wait_edge_events(timeout_s):
            return None
        events = self._request.read_edge_events()
        return _monotonic_to_wall(events[-1].timestamp_ns * 1e-9)

    def close(self) -> None:
        """Release the line."""
        self._request.release()


class SimulatedInterrupt:
    """INT1 of the register-level simulated ADXL345 ``chip``."""

    def __init__(self, chip: Any) -> None:
        self.chip = chip

    def wait_edge(self, timeout_s: float) -> Optional[float]:
        """Return the wall-clock time the watermark was reached, or None after ``timeout_s``."""
        if not self.chip.wait_int1(timeout_s):
            return None
        return _monotonic_to_wall(self.chip.watermark_time())

    def close(self) -> None:
        """Nothing to release."""
