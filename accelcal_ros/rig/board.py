"""
The chessboard target: size, corner coordinates and square colours.

Board frame (metres): origin at the first inner corner, x along a row of inner corners
(``cols`` of them), y along a column (``rows``), z = x cross y. Printed as seen from its
front, x runs right and y down, so z points *into* the board (away from a viewer).
Square ``(i, j)`` (``i = 0..cols``, ``j = 0..rows``) covers
``x in [(i - 1) s, i s)``, ``y in [(j - 1) s, j s)`` and is black when ``i + j`` is even:
the square diagonally before the first inner corner is black. With ``cols + rows`` odd
(one count even, the other odd, as OpenCV recommends) a half turn of the board swaps
black and white, which is how :mod:`.detect` tells the two orderings apart.
"""
from dataclasses import dataclass
import re

from accelcal_ros.errors import InputError
import numpy as np


@dataclass(frozen=True)
class Board:
    """A chessboard of ``cols x rows`` inner corners (as OpenCV counts) and square ``square_m``."""

    cols: int
    rows: int
    square_m: float

    def __post_init__(self) -> None:
        """Check the counts (>= 3, one even and one odd) and the square size (> 0)."""
        if self.cols < 3 or self.rows < 3:
            raise InputError(f'board {self.cols}x{self.rows}: needs at least 3x3 inner corners')
        if (self.cols + self.rows) % 2 == 0:
            raise InputError(f'board {self.cols}x{self.rows}: one count of inner corners must '
                             'be even and the other odd (e.g. 9x6), otherwise a half turn of '
                             'the board looks the same and its orientation is ambiguous')
        if not np.isfinite(self.square_m) or self.square_m <= 0:
            raise InputError(f'board square size must be a positive length in metres, '
                             f'got {self.square_m!r}')

    @property
    def pattern_size(self) -> tuple:
        """``(cols, rows)`` as OpenCV's ``patternSize``."""
        return self.cols, self.rows

    @property
    def count(self) -> int:
        """Number of inner corners."""
        return self.cols * self.rows

    def object_points(self) -> np.ndarray:
        """Inner corners ``(cols*rows, 3)`` in the board frame (m), row by row (OpenCV order)."""
        jj, ii = np.mgrid[0:self.rows, 0:self.cols]
        pts = np.stack([ii.ravel(), jj.ravel(), np.zeros(self.count)], axis=1)
        return pts * self.square_m

    def outline_points(self, margin_squares: float = 1.0) -> np.ndarray:
        """Corners of the printed area (squares plus ``margin_squares`` of white), (4, 3)."""
        m = (1.0 + margin_squares) * self.square_m
        x0, y0 = -m, -m
        x1 = (self.cols - 1) * self.square_m + m
        y1 = (self.rows - 1) * self.square_m + m
        return np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])

    def centre(self) -> np.ndarray:
        """Centre of the inner corners in the board frame (m)."""
        return np.array([(self.cols - 1) / 2.0, (self.rows - 1) / 2.0, 0.0]) * self.square_m

    def reflectance(self, x_m: np.ndarray, y_m: np.ndarray, margin_squares: float = 1.0,
                    background: float = np.nan) -> np.ndarray:
        """
        Brightness in [0, 1] at board points ``(x_m, y_m)``: 0 black, 1 white.

        The squares, then a white margin of ``margin_squares``; outside it ``background``.
        """
        s = self.square_m
        i = np.floor(x_m / s).astype(np.int64) + 1
        j = np.floor(y_m / s).astype(np.int64) + 1
        inside = (i >= 0) & (i <= self.cols) & (j >= 0) & (j <= self.rows)
        value = np.where((i + j) % 2 == 0, 0.0, 1.0)
        m = margin_squares * s
        on_paper = ((x_m >= -s - m) & (x_m < self.cols * s + m)
                    & (y_m >= -s - m) & (y_m < self.rows * s + m))
        return np.where(inside, value, np.where(on_paper, 1.0, background))


def parse_board_size(text: str) -> tuple:
    """Parse ``COLSxROWS`` (inner corners, e.g. ``9x6``) into ``(cols, rows)``."""
    match = re.fullmatch(r'\s*(\d+)\s*[xX]\s*(\d+)\s*', str(text))
    if not match:
        raise InputError(f'board size must be COLSxROWS inner corners (e.g. 9x6), got {text!r}')
    return int(match.group(1)), int(match.group(2))
