"""
The ADXL345's built-in self-test (pure, no ROS): is the sensor itself healthy.

Datasheet (Rev. G, "Self-Test"): setting DATA_FORMAT.SELF_TEST exerts an electrostatic
force on the proof mass that shifts each axis' output; the shift ``on - off`` must fall
in Table 15's limits (LSB, ±2 g 10-bit or full resolution, at VS = 2.5 V: x 50..540,
y -540..-50, z 75..875), scaled for the supply voltage by Table 14 (x and y: 0.64, 1.00,
1.77, 2.11; z: 0.8, 1.00, 1.47, 1.69 at 2.0, 2.5, 3.3, 3.6 V; linear in between). The
part must be in normal power at 100 to 800 Hz or 3200 Hz; full resolution at ±16 g
leaves room for the shift. Procedure: average ``samples`` readings with the self-test
off, set it, discard ``settle_s`` (the output filter settles), average ``samples``
readings with it on, clear it. Readings come from the FIFO (stream mode), so the host's
timing does not matter.
"""
from dataclasses import dataclass
import time
from typing import Any, Callable, List, Tuple

from accelcal_ros.errors import InputError
from accelcal_ros.sensor.datasheet import FULL_RES_G_PER_LSB
import numpy as np

SELF_TEST_LIMITS_LSB_2V5 = ((50.0, 540.0), (-540.0, -50.0), (75.0, 875.0))
"""Table 15: self-test output change (LSB), x/y/z, at VS = 2.5 V, full resolution."""
SUPPLY_VOLTAGES_V = (2.0, 2.5, 3.3, 3.6)
SCALE_XY = (0.64, 1.00, 1.77, 2.11)
SCALE_Z = (0.8, 1.00, 1.47, 1.69)
"""Table 14: self-test output scale factors at the supply voltages above."""
SELF_TEST_RATE_HZ = 100.0
SELF_TEST_RANGE_G = 16
AXES = ('x', 'y', 'z')


def self_test_scale(supply_voltage_v: float) -> np.ndarray:
    """Table 14's scale factors (x, y, z) at ``supply_voltage_v`` (linear between rows)."""
    low, high = SUPPLY_VOLTAGES_V[0], SUPPLY_VOLTAGES_V[-1]
    if not low <= supply_voltage_v <= high:
        raise InputError(f"supply voltage {supply_voltage_v:g} V is outside the ADXL345's "
                         f'{low:g}..{high:g} V')
    xy = float(np.interp(supply_voltage_v, SUPPLY_VOLTAGES_V, SCALE_XY))
    z = float(np.interp(supply_voltage_v, SUPPLY_VOLTAGES_V, SCALE_Z))
    return np.array([xy, xy, z])


def self_test_limits_lsb(supply_voltage_v: float) -> np.ndarray:
    """``(3, 2)`` array of (low, high) output change limits in LSB at the supply voltage."""
    return np.asarray(SELF_TEST_LIMITS_LSB_2V5) * self_test_scale(supply_voltage_v)[:, None]


@dataclass
class SelfTestResult:
    """Measured change (LSB, 3.9 mg each) per axis, its limits, and pass/fail."""

    change_lsb: np.ndarray
    limits_lsb: np.ndarray
    supply_voltage_v: float

    @property
    def axis_passed(self) -> List[bool]:
        """Whether each axis' change falls in its limits."""
        return [bool(lo <= c <= hi) for c, (lo, hi) in zip(self.change_lsb, self.limits_lsb)]

    @property
    def passed(self) -> bool:
        """All three axes in their limits."""
        return all(self.axis_passed)

    def summary(self) -> str:
        """One line: verdict, then per axis the change, its limits and pass/fail."""
        parts = []
        for name, change, (lo, hi), ok in zip(AXES, self.change_lsb, self.limits_lsb,
                                              self.axis_passed):
            parts.append(f'{name} {change:+.0f} LSB ({change * FULL_RES_G_PER_LSB:+.2f} g, '
                         f'limits {lo:.0f}..{hi:.0f}) {"pass" if ok else "FAIL"}')
        verdict = 'passed' if self.passed else 'FAILED'
        return (f'ADXL345 self-test {verdict} at VS = {self.supply_voltage_v:g} V: '
                + '; '.join(parts))


def _mean_counts(device: Any, samples: int, settle_s: float, rate_hz: float,
                 sleep: Callable[[float], None]) -> np.ndarray:
    """Discard ``settle_s`` of FIFO entries, then average ``samples`` entries (LSB)."""
    sleep(settle_s)
    device.read_fifo()
    collected: List[np.ndarray] = []
    count = 0
    while count < samples:
        sleep(16.0 / rate_hz)   # half the FIFO
        batch, _ = device.read_fifo()
        collected.append(batch)
        count += len(batch)
    return np.concatenate(collected)[:samples].mean(axis=0) / FULL_RES_G_PER_LSB


def measure_self_test(device: Any, samples: int = 50, settle_s: float = 0.1,
                      rate_hz: float = SELF_TEST_RATE_HZ,
                      sleep: Callable[[float], None] = time.sleep) -> Tuple[np.ndarray,
                                                                            np.ndarray]:
    """Return ``(mean off, mean on)`` counts (LSB) of the self-test on ``device``."""
    device.configure(rate_hz, SELF_TEST_RANGE_G, fifo=True)
    try:
        off = _mean_counts(device, samples, settle_s, rate_hz, sleep)
        device.set_self_test(True)
        on = _mean_counts(device, samples, settle_s, rate_hz, sleep)
    finally:
        device.set_self_test(False)
    return off, on


def run_self_test(device: Any, supply_voltage_v: float, samples: int = 50,
                  settle_s: float = 0.1, sleep: Callable[[float], None] = time.sleep
                  ) -> SelfTestResult:
    """Run the self-test on a checked ``device`` (:class:`Adxl345`) and judge each axis."""
    limits = self_test_limits_lsb(supply_voltage_v)
    off, on = measure_self_test(device, samples, settle_s, sleep=sleep)
    return SelfTestResult(on - off, limits, float(supply_voltage_v))
