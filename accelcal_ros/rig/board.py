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
from typing import Tuple

from accelcal_ros.errors import InputError
import numpy as np
from numpy.typing import ArrayLike

#: most inner corners along one side of the board (OpenCV's detector overflows, even
#: crashes, for counts whose product passes 2**31; real printed boards have < 30)
MAX_INNER_CORNERS = 100
#: smallest square side (m) a calibration is solved for (below, the extrinsics lose
#: their scale and come out wrong; printed boards have squares of millimetres and up)
MIN_SQUARE_M = 1e-3


@dataclass(frozen=True)
class Board:
    """A chessboard of ``cols x rows`` inner corners (as OpenCV counts) and square ``square_m``."""

    cols: int
    rows: int
    square_m: float

    def __post_init__(self) -> None:
        """Check the counts (3 .. 100, one even and one odd) and the square size (>= 1 mm)."""
        if self.cols < 3 or self.rows < 3:
            raise InputError(f'board {self.cols}x{self.rows}: needs at least 3x3 inner corners')
        if (self.cols + self.rows) % 2 == 0:
            raise InputError(f'board {self.cols}x{self.rows}: one count of inner corners must '
                             'be even and the other odd (e.g. 9x6), otherwise a half turn of '
                             'the board looks the same and its orientation is ambiguous')
        if max(self.cols, self.rows) > MAX_INNER_CORNERS:
            raise InputError(f'board {self.cols}x{self.rows}: at most {MAX_INNER_CORNERS} '
                             'inner corners per side')
        if not np.isfinite(self.square_m) or self.square_m < MIN_SQUARE_M:
            raise InputError(f'board square size must be a length of at least {MIN_SQUARE_M:g} '
                             f'm, got {self.square_m!r}')

    @property
    def pattern_size(self) -> tuple:
        """``(cols, rows)`` as OpenCV's ``patternSize``."""
        return self.cols, self.rows

    @property
    def count(self) -> int:
        """Return the number of inner corners."""
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
                    background: float = np.nan, width_x_m: ArrayLike = 0.0,
                    width_y_m: ArrayLike = 0.0) -> np.ndarray:
        """
        Brightness in [0, 1] at board points ``(x_m, y_m)``: 0 black, 1 white.

        The squares, then a white margin of ``margin_squares``; outside it ``background``.
        With footprint widths ``width_x_m``, ``width_y_m`` (> 0) the squares are box-filtered
        over them (anti-aliasing): each axis' square wave ``q = +-1`` becomes
        ``q min(1, 2 |d| / width)`` with ``d`` the distance to the nearest edge, and the
        checker is ``(1 - q_x q_y) / 2`` (exact for an axis-aligned footprint).
        """
        s = self.square_m
        gx = np.asarray(x_m) / s + 1.0
        gy = np.asarray(y_m) / s + 1.0
        wx = np.maximum(np.asarray(width_x_m) / s, 1e-12)
        wy = np.maximum(np.asarray(width_y_m) / s, 1e-12)
        qx = self._smoothed_wave(gx, wx, self.cols)
        qy = self._smoothed_wave(gy, wy, self.rows)
        # fraction of the footprint on the squares (the rest is the white margin)
        cover = (np.clip(0.5 + np.minimum(gx, self.cols + 1 - gx) / wx, 0.0, 1.0)
                 * np.clip(0.5 + np.minimum(gy, self.rows + 1 - gy) / wy, 0.0, 1.0))
        value = cover * (0.5 - 0.5 * qx * qy) + (1.0 - cover)
        m = margin_squares * s
        on_paper = ((x_m >= -s - m) & (x_m < self.cols * s + m)
                    & (y_m >= -s - m) & (y_m < self.rows * s + m))
        return np.where(on_paper, value, background)

    @staticmethod
    def _smoothed_wave(g: np.ndarray, width: np.ndarray, count: int) -> np.ndarray:
        # +1 on even squares, -1 on odd ones, box-filtered across the inner edges 1..count
        square = np.floor(np.clip(g, 0.0, count + 0.5))
        edge = np.clip(np.rint(g), 1, count)
        return (np.where(square % 2 == 0, 1.0, -1.0)
                * np.minimum(1.0, 2.0 * np.abs(g - edge) / width))


def parse_board_size(text: str) -> Tuple[int, int]:
    """Parse ``COLSxROWS`` (inner corners, e.g. ``9x6``) into ``(cols, rows)``."""
    match = re.fullmatch(r'\s*(\d+)\s*[xX]\s*(\d+)\s*', str(text))
    if not match:
        raise InputError(f'board size must be COLSxROWS inner corners (e.g. 9x6), got {text!r}')
    cols, rows = int(match.group(1)), int(match.group(2))
    if max(cols, rows) > MAX_INNER_CORNERS:
        raise InputError(f'board {text.strip()}: at most {MAX_INNER_CORNERS} inner corners per '
                         'side')
    return cols, rows
