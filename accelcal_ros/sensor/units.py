"""
Standard gravity and unit conversions: the package's one value of g.

Readings in g are multiples of standard gravity (paper A's unit of acceleration); ROS
messages carry m/s^2 (REP-103).
"""
import numpy as np
from numpy.typing import ArrayLike

STANDARD_GRAVITY_M_S2 = 9.80665
"""One g in m/s^2 (standard gravity, exact by definition)."""


def g_to_mps2(values_g: ArrayLike) -> np.ndarray:
    """Convert accelerations from g to m/s^2 (1 g = 9.80665 m/s^2)."""
    return np.asarray(values_g, dtype=float) * STANDARD_GRAVITY_M_S2


def mps2_to_g(values_mps2: ArrayLike) -> np.ndarray:
    """Convert accelerations from m/s^2 to g."""
    return np.asarray(values_mps2, dtype=float) / STANDARD_GRAVITY_M_S2
