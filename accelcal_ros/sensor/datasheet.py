"""
ADXL345 datasheet facts (Analog Devices, Rev. G), in one place.

- Full resolution: 3.9 mg/LSB (typical) at every range (Table 1, "Sensitivity").
- Output data rates: 6.25 Hz to 3200 Hz in factors of two (Table 7, BW_RATE).
- Ranges: +-2, 4, 8, 16 g (DATA_FORMAT).
- Noise at ODR = 100 Hz: 0.75 LSB rms on x and y, 1.1 LSB rms on z (Table 1), i.e. 2.9 mg
  and 4.3 mg. White noise over a bandwidth of ODR/2 scales with ``sqrt(ODR / 100 Hz)``.
  The figure is the noise of the quantised output.
"""
import math
from typing import Tuple

import numpy as np

FULL_RES_G_PER_LSB = 0.0039
"""Full-resolution scale factor, 3.9 mg/LSB (typical)."""
NOISE_LSB_RMS_100HZ = (0.75, 0.75, 1.1)
"""Output noise at ODR = 100 Hz, LSB rms, x/y/z."""
OUTPUT_DATA_RATES_HZ = (6.25, 12.5, 25.0, 50.0, 100.0, 200.0, 400.0, 800.0, 1600.0, 3200.0)
"""Output data rates selectable in BW_RATE (Hz)."""
RANGES_G = (2, 4, 8, 16)
"""Measurement ranges (+- g)."""
FIFO_DEPTH = 32
"""Samples the FIFO holds."""


def datasheet_noise_std_g(rate_hz: float) -> np.ndarray:
    """Per-axis output noise standard deviation (g, x/y/z) at output data rate ``rate_hz``."""
    factor = FULL_RES_G_PER_LSB * math.sqrt(rate_hz / 100.0)
    return np.array([v * factor for v in NOISE_LSB_RMS_100HZ])


NOISE_STD_100HZ_G: Tuple[float, ...] = tuple(datasheet_noise_std_g(100.0).tolist())
"""Output noise at 100 Hz in g (2.9, 2.9, 4.3 mg): the default noise where none is given."""
