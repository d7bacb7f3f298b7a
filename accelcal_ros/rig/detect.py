"""
Chessboard detection with sub-pixel corners and one ordering tied to the board frame.

``cv2.findChessboardCorners`` returns the ``cols x rows`` inner corners row by row, but
it may start from any end: the same board seen by two cameras can come back mirrored or
turned by half a turn. Corners are therefore put in the board frame's order
(:mod:`.board`) by two tests, so every camera's view of a pose names each corner alike:

1. **Handedness.** The board is seen from its front, where its x axis (along a row)
   and y axis (along a column) appear in the image as they are printed (x right, y
   down): the image cross product ``(c[1] - c[0]) x (c[cols] - c[0])`` is positive.
   A negative one means the rows came back reversed.
2. **Half turn.** With ``cols + rows`` odd, the squares between inner corners ``(i, j)``
   and ``(i + 1, j + 1)`` are black when ``i + j`` is even (:mod:`.board`); a half turn
   swaps the colours. The mean grey at the interior squares' centres that should be
   black is compared with the mean at those that should be white.
"""
from dataclasses import dataclass
from typing import List, Optional, Tuple

from accelcal_ros.rig.board import Board
import cv2
import numpy as np

FIND_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_FAST_CHECK
"""Classic detector flags (without NORMALIZE_IMAGE, which costs ~1 s on a partial board)."""
MIN_CONTRAST = 20.0
"""Grey levels the 'white' interior squares must exceed the 'black' ones by."""


@dataclass
class Detection:
    """Corners ``(cols*rows, 2)`` in pixels (OpenCV convention), in board-frame order."""

    corners: np.ndarray
    contrast: float
    reordered: str = ''


def _order(corners: np.ndarray, board: Board, gray: np.ndarray) -> Tuple[np.ndarray, float,
                                                                         str]:
    grid = corners.reshape(board.rows, board.cols, 2)
    notes = []
    a = grid[0, 1] - grid[0, 0]
    b = grid[1, 0] - grid[0, 0]
    if a[0] * b[1] - a[1] * b[0] < 0:
        grid = grid[:, ::-1]
        notes.append('mirrored')
    centres = (grid[:-1, :-1] + grid[:-1, 1:] + grid[1:, :-1] + grid[1:, 1:]) / 4.0
    jj, ii = np.mgrid[0:board.rows - 1, 0:board.cols - 1]
    black = (ii + jj) % 2 == 0
    samples = np.array([cv2.getRectSubPix(gray, (3, 3), (float(x), float(y))).mean()
                        for x, y in centres.reshape(-1, 2)]).reshape(black.shape)
    contrast = float(samples[~black].mean() - samples[black].mean())
    if contrast < 0:
        grid = grid[::-1, ::-1]
        contrast = -contrast
        notes.append('half turn')
    return grid.reshape(-1, 2), contrast, ' + '.join(notes)


def subpixel_window(corners: np.ndarray, board: Board) -> int:
    """Half-size (px) of the cornerSubPix window: 40 % of the smallest corner spacing, 2..11."""
    grid = corners.reshape(board.rows, board.cols, 2)
    spacing = min(np.linalg.norm(np.diff(grid, axis=1), axis=2).min(),
                  np.linalg.norm(np.diff(grid, axis=0), axis=2).min())
    return int(np.clip(np.floor(0.4 * spacing), 2, 11))


def detect_board(gray: np.ndarray, board: Board) -> Optional[Detection]:
    """
    Find the board in an 8-bit grey image; return its ordered corners or None.

    The classic detector first, the sector-based one (``findChessboardCornersSB``) when
    it fails; corners are refined with ``cv2.cornerSubPix`` (window from the spacing);
    a board whose interior squares show no black/white contrast is rejected (None).
    """
    found, corners = cv2.findChessboardCorners(gray, board.pattern_size, flags=FIND_FLAGS)
    if (not found or corners is None) and hasattr(cv2, 'findChessboardCornersSB'):
        found, corners = cv2.findChessboardCornersSB(gray, board.pattern_size)
    if not found or corners is None or len(corners) != board.count:
        return None
    corners = corners.reshape(-1, 2).astype(np.float32)
    win = subpixel_window(corners, board)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    refined = cv2.cornerSubPix(gray, corners.reshape(-1, 1, 2).copy(), (win, win), (-1, -1),
                               criteria).reshape(-1, 2)
    ordered, contrast, notes = _order(refined.astype(np.float64), board, gray)
    if contrast < MIN_CONTRAST:
        return None
    return Detection(ordered, contrast, notes)


def guess_board_size(gray: np.ndarray, board: Board, spread: int = 2) -> List[Tuple[int, int]]:
    """
    Return the inner-corner sizes near ``board`` (counts +-``spread``, swapped) found in ``gray``.

    Used only to explain a failed detection ("found 8x6, not 9x6").
    """
    found = []
    sizes = set()
    for c in range(max(3, board.cols - spread), board.cols + spread + 1):
        for r in range(max(3, board.rows - spread), board.rows + spread + 1):
            sizes.add((c, r))
            sizes.add((r, c))
    sizes.discard(board.pattern_size)
    for size in sorted(sizes, key=lambda s: -s[0] * s[1]):
        ok, _ = cv2.findChessboardCorners(gray, size, flags=FIND_FLAGS
                                          | cv2.CALIB_CB_FAST_CHECK)
        if ok:
            found.append(size)
            break
    return found
