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

``SensorModel()`` is the identity (uncalibrated) model. Paper A's Table-1 estimates are
named constants here (:data:`PAPER_A_TABLE1`); :func:`paper_a_model` builds one of them
(the simulator's truth is ``paper_a_model(500)``, passed explicitly).
"""
from dataclasses import dataclass, field
import math
from typing import Dict, Tuple

from accelcal_ros.errors import InputError
import numpy as np
from numpy.typing import ArrayLike

MODELS = ('diagonal', 'full')
"""Calibration models: ``diagonal`` (paper A: scale, bias) and ``full`` (+ misalignment)."""

PAPER_K500_SCALE = (0.928, 0.909, 0.896)
"""Paper A Table 1, K = 500 positions: scale factors k (the package's sim truth)."""
PAPER_K500_BIAS = (-0.025, -0.037, -0.056)
"""Paper A Table 1, K = 500 positions: biases b, in g."""
PAPER_K300_SCALE = (0.822, 0.823, 0.886)
"""Paper A Table 1, K = 300 positions: scale factors k."""
PAPER_K300_BIAS = (-0.001, 0.016, -0.062)
"""Paper A Table 1, K = 300 positions: biases b, in g."""
PAPER_K100_SCALE = (0.823, 0.921, 0.807)
"""Paper A Table 1, K = 100 positions: scale factors k."""
PAPER_K100_BIAS = (0.026, -0.030, -0.088)
"""Paper A Table 1, K = 100 positions: biases b, in g."""
PAPER_A_TABLE1: Dict[int, Tuple[Tuple[float, float, float], Tuple[float, float, float]]] = {
    500: (PAPER_K500_SCALE, PAPER_K500_BIAS),
    300: (PAPER_K300_SCALE, PAPER_K300_BIAS),
    100: (PAPER_K100_SCALE, PAPER_K100_BIAS),
}
"""Paper A Table 1: positions K -> (scale k, bias b in g)."""

GRAVITY_FIT_TOLERANCE_G = 0.03
"""Default tolerance of :meth:`SensorModel.gravity_fit` on the mean and spread of |f| (g)."""


def misalignment_matrix(misalignment: ArrayLike) -> np.ndarray:
    """Return the full model's upper-triangular ``T`` from ``[m_yz, m_zy, m_zx]`` (rad)."""
    m_yz, m_zy, m_zx = np.asarray(misalignment, dtype=float)
    return np.array([[1.0, -m_yz, m_zy], [0.0, 1.0, -m_zx], [0.0, 0.0, 1.0]])


@dataclass
class SensorModel:
    """
    Scale ``k`` [3], bias ``b`` [3] (g) and misalignment ``m`` [3] (rad, full model).

    The default is the identity: unit scale, zero bias, no misalignment.
    """

    scale: np.ndarray = field(default_factory=lambda: np.ones(3))
    bias: np.ndarray = field(default_factory=lambda: np.zeros(3))
    misalignment: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
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
    def identity(cls) -> 'SensorModel':
        """Return the uncalibrated model: unit scale, zero bias, no misalignment."""
        return cls(np.ones(3), np.zeros(3), np.zeros(3))

    def correction_matrix(self) -> np.ndarray:
        """``C = T diag(1/k)`` so that ``f = C (a - b)``."""
        return misalignment_matrix(self.misalignment) @ np.diag(1.0 / self.scale)

    def correct(self, raw: ArrayLike) -> np.ndarray:
        """Specific force ``f`` (g) from raw readings ``a`` (g), shape ``(..., 3)``."""
        raw = np.asarray(raw, dtype=float)
        return (raw - self.bias) @ self.correction_matrix().T

    def distort(self, force: ArrayLike) -> np.ndarray:
        """Raw reading ``a`` (g, before noise) of a specific force ``f`` (g), ``(..., 3)``."""
        force = np.asarray(force, dtype=float)
        sensitivity = np.diag(self.scale) @ np.linalg.inv(misalignment_matrix(self.misalignment))
        return force @ sensitivity.T + self.bias

    def is_identity(self) -> bool:
        """Return True for the uncalibrated model (unit scale, zero bias and misalignment)."""
        return bool(np.all(self.scale == 1.0) and not np.any(self.bias)
                    and not np.any(self.misalignment))

    def gravity_fit(self, raw_g: ArrayLike,
                    tolerance_g: float = GRAVITY_FIT_TOLERANCE_G) -> 'GravityFit':
        """
        Say whether this calibration fits still readings ``raw_g`` (N, 3) in g.

        At rest the corrected specific force has ``|f| = 1`` g in every orientation. A
        calibration of another sensor (or none) leaves ``|f|`` off 1 g by an amount that
        depends on the orientation: the mean and spread of ``|f|`` over the readings (or
        over the mean readings of still positions) tell. NaN rows are ignored.
        """
        raw = np.asarray(raw_g, dtype=float).reshape(-1, 3)
        raw = raw[np.all(np.isfinite(raw), axis=1)]
        norms = np.linalg.norm(self.correct(raw), axis=1) if raw.size else np.empty(0)
        if norms.size == 0:
            return GravityFit(0, math.nan, math.nan, math.nan, float(tolerance_g))
        return GravityFit(int(norms.size), float(norms.mean()), float(norms.std()),
                          float(np.max(np.abs(norms - 1.0))), float(tolerance_g))


@dataclass(frozen=True)
class GravityFit:
    """How well a calibration fits still readings: statistics of ``|f|`` in g."""

    count: int
    mean_norm_g: float
    std_norm_g: float
    max_deviation_g: float
    """Largest ``| |f| - 1 |`` (g)."""
    tolerance_g: float

    @property
    def fits(self) -> bool:
        """Return True when ``|mean - 1|`` and the spread are both within the tolerance."""
        return (self.count > 0 and abs(self.mean_norm_g - 1.0) <= self.tolerance_g
                and self.std_norm_g <= self.tolerance_g)

    def message(self) -> str:
        """Return one line for a warning: the figures and what to do."""
        if self.count == 0:
            return 'no finite readings to check the calibration against'
        verdict = 'fits' if self.fits else 'does not fit'
        text = (f'the accelerometer calibration {verdict} these readings: |g| after '
                f'correction {self.mean_norm_g:.4f} +- {self.std_norm_g:.4f} g over '
                f'{self.count} readings (worst {self.max_deviation_g:.4f} g off 1 g; '
                f'tolerance {self.tolerance_g:g} g)')
        if not self.fits:
            text += '; is it the calibration of this sensor?'
        return text


def paper_a_model(positions: int = 500) -> SensorModel:
    """Return paper A's Table-1 estimate for ``positions`` in (100, 300, 500) (diagonal)."""
    if positions not in PAPER_A_TABLE1:
        raise InputError(f'paper A Table 1 has K = 100, 300 or 500 positions, not {positions}')
    scale, bias = PAPER_A_TABLE1[positions]
    return SensorModel(np.array(scale), np.array(bias))
