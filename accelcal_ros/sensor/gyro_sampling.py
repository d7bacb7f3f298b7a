r"""
A FIFO-less gyro read once per accelerometer poll: its low-pass, stamps and interpolation.

The GY-85's ITG-3205 has no FIFO; the driver reads its newest sample once per poll of
the ADXL345 (:mod:`accelcal_ros.driver.gyro_source`). Pure core shared by the driver
and the drive simulation (:mod:`accelcal_ros.sensor.drive_sim`), so the study measures
what the driver publishes:

* the chip samples at 1 kHz with its digital low-pass (``DLPF_CFG``) set below half the
  poll rate (:func:`dlpf_for_poll`): what the reads skip would otherwise alias;
* a read is stamped at the read time minus the low-pass's group delay
  (:data:`DLPF_DELAY_S`);
* each accelerometer sample gets the rate on the line through the last two reads at its
  stamp (:func:`rates_at`), continued over the delay plus one chip period after the
  newest read (the newest samples lie there), then held.
"""
from typing import List, Sequence, Tuple

DLPF_BANDWIDTHS_HZ = {0: 256.0, 1: 188.0, 2: 98.0, 3: 42.0, 4: 20.0, 5: 10.0, 6: 5.0}
"""ITG-3205 ``DLPF_CFG`` codes: low-pass bandwidth (Hz; product specification)."""
DLPF_DELAY_S = {0: 0.00098, 1: 0.0019, 2: 0.0028, 3: 0.0048, 4: 0.0083, 5: 0.0134, 6: 0.0186}
"""Group delay of each low-pass (s): InvenSense's gyro DLPF (the MPU-6000 register map
tabulates it for the same codes)."""

Read = Tuple[float, float, float, float]
"""A stamped read: ``(t, x, y, z)`` (s, rad/s)."""


def dlpf_for_rate(rate_hz: float) -> int:
    """Return the DLPF_CFG code whose bandwidth is the widest below half ``rate_hz``."""
    for code in (1, 2, 3, 4, 5, 6):
        if DLPF_BANDWIDTHS_HZ[code] <= rate_hz / 2.0:
            return code
    return 6


def rates_at(reads: Sequence[Read], stamps: Sequence[float], delay_s: float,
             chip_period_s: float) -> List[Tuple[float, float, float]]:
    """Return the rate at each stamp from the last two stamped ``reads`` (see the module)."""
    if not reads:
        return []
    t1, x1, y1, z1 = reads[-1]
    if len(reads) == 1 or reads[-1][0] <= reads[-2][0]:
        return [(x1, y1, z1)] * len(stamps)
    t0, x0, y0, z0 = reads[-2]
    span = t1 - t0
    w_max = 1.0 + (delay_s + chip_period_s) / span
    out = []
    for s in stamps:
        w = min(w_max, max(0.0, (s - t0) / span))
        out.append((x0 + w * (x1 - x0), y0 + w * (y1 - y0), z0 + w * (z1 - z0)))
    return out
