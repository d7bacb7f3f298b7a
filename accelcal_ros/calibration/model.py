r"""
The accelerometer error model shared by the simulator (truth) and the calibration.

Paper A, eq. (1): ``a = K g + b + n`` with ``K = diag(k)`` (scale), ``b`` bias, ``n``
noise, all in units of g. Correction: ``g_i = (a_i - b_i) / k_i``. Here ``g`` is the
specific force ``f`` in the sensor frame (REP-145: +1 g up at rest; see
:mod:`accelcal_ros.frames`).

The ``full`` model adds three small axis-misalignment angles as in imu_tk (Tedaldi et
al., ICRA 2014): the sensing axes are not exactly orthogonal, which on a real ADXL345
gives about 1 % cross-axis coupling. With the upper-triangular matrix

.. math::

    T = \begin{bmatrix} 1 & -m_{yz} & m_{zy} \\ 0 & 1 & -m_{zx} \\ 0 & 0 & 1 \end{bmatrix}

the corrected specific force is ``f = T diag(1/k) (a - b)`` and the raw reading of a
specific force is ``a = diag(k) T^{-1} f + b``. With ``m = 0`` both reduce to paper A.
"""
from dataclasses import dataclass, field

from accelcal_ros.errors import InputError
import numpy as np

PAPER_K500_SCALE = (0.928, 0.909, 0.896)
"""Paper A Table 1, K = 500 positions: scale factors k (the package's sim truth)."""
PAPER_K500_BIAS = (-0.025, -0.037, -0.056)
"""Paper A Table 1, K = 500 positions: biases b, in g."""
PAPER_K300_SCALE = (0.822, 0.823, 0.886)
PAPER_K300_BIAS = (-0.001, 0.016, -0.062)
PAPER_K100_SCALE = (0.823, 0.921, 0.807)
PAPER_K100_BIAS = (0.026, -0.030, -0.088)


def misalignment_matrix(misalignment):
    """Return the full model's upper-triangular ``T`` from ``[m_yz, m_zy, m_zx]`` (rad)."""
    m_yz, m_zy, m_zx = np.asarray(misalignment, dtype=float)
    return np.array([[1.0, -m_yz, m_zy], [0.0, 1.0, -m_zx], [0.0, 0.0, 1.0]])


@dataclass
class SensorModel:
    """Scale ``k`` [3], bias ``b`` [3] (g) and misalignment ``m`` [3] (rad, full model)."""

    scale: np.ndarray = field(default_factory=lambda: np.array(PAPER_K500_SCALE))
    bias: np.ndarray = field(default_factory=lambda: np.array(PAPER_K500_BIAS))
    misalignment: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self):
        """Convert to float arrays and check shapes and values."""
        for name in ('scale', 'bias', 'misalignment'):
            value = np.asarray(getattr(self, name), dtype=float).reshape(-1)
            if value.shape != (3,):
                raise InputError(f'{name}: expected 3 values, got {value.size}')
            if not np.all(np.isfinite(value)):
                raise InputError(f'{name}: contains NaN or infinity')
            setattr(self, name, value)
        if np.any(self.scale <= 0.0):
            raise InputError(f'scale: every factor must be positive, got {self.scale}')

    @classmethod
    def identity(cls):
        """Return the uncalibrated model: unit scale, zero bias, no misalignment."""
        return cls(np.ones(3), np.zeros(3), np.zeros(3))

    def correction_matrix(self):
        """``C = T diag(1/k)`` so that ``f = C (a - b)``."""
        return misalignment_matrix(self.misalignment) @ np.diag(1.0 / self.scale)

    def correct(self, raw):
        """Specific force ``f`` (g) from raw readings ``a`` (g), shape ``(..., 3)``."""
        raw = np.asarray(raw, dtype=float)
        return (raw - self.bias) @ self.correction_matrix().T

    def distort(self, force):
        """Raw reading ``a`` (g, before noise) of a specific force ``f`` (g), ``(..., 3)``."""
        force = np.asarray(force, dtype=float)
        sensitivity = np.diag(self.scale) @ np.linalg.inv(misalignment_matrix(self.misalignment))
        return force @ sensitivity.T + self.bias
