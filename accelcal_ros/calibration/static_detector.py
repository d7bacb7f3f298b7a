"""
Streaming still-dwell detector: moving variance with a minimum still time (pure core).

Samples (time in s, raw acceleration in g, sensor frame) are first averaged over short
blocks of ``block_s`` (20 ms) so that the detector sees the same noise at every output
data rate (the ADXL345's white noise averaged over 20 ms is about 3 mg at 100 Hz as at
3200 Hz). The sensor is *still* while the standard deviation of the block means over the
last ``window_s`` is below ``threshold_g`` on every axis. A still *segment* runs from the
start of the first still window until the window stops being still; when it ends, its
last ``window_s`` is trimmed (the motion that ended it had already begun there).

Invalid samples are not used and are counted in :attr:`StaticDetector.rejected`: a NaN
or infinite sample (a read glitch) is skipped; a sample with any axis at or beyond
``saturation_g`` (a shock) also ends the current segment, as motion does. A time stamp
going backwards or jumping by more than ``max_gap_s`` ends the segment too.
"""
from collections import deque
from dataclasses import dataclass
from typing import List, Optional

import numpy as np


@dataclass
class Block:
    """Sums of the samples of one block."""

    t_start: float
    t_end: float
    count: int
    total: np.ndarray
    total_sq: np.ndarray

    @property
    def mean(self):
        """Return the block's mean reading (g)."""
        return self.total / self.count


@dataclass
class SegmentStats:
    """Mean reading of a still segment and its noise."""

    t_start: float
    t_end: float
    samples: int
    mean_g: np.ndarray
    std_g: np.ndarray
    """Sample standard deviation per axis (g)."""

    @property
    def std_of_mean_g(self):
        """Return the standard deviation of the mean, ``std / sqrt(N)`` (g)."""
        return self.std_g / np.sqrt(max(self.samples, 1))

    @property
    def duration_s(self):
        """Return the time spanned by the segment (s)."""
        return self.t_end - self.t_start


def stats_of_blocks(blocks):
    """Return the :class:`SegmentStats` of a list of blocks (None if empty)."""
    if not blocks:
        return None
    count = sum(b.count for b in blocks)
    total = np.sum([b.total for b in blocks], axis=0)
    total_sq = np.sum([b.total_sq for b in blocks], axis=0)
    mean = total / count
    var = (total_sq - count * mean * mean) / max(count - 1, 1)
    return SegmentStats(blocks[0].t_start, blocks[-1].t_end, count, mean,
                        np.sqrt(np.clip(var, 0.0, None)))


class Segment:
    """One still segment being built: its blocks, an id, and whether it has ended."""

    def __init__(self, segment_id, blocks):
        self.segment_id = segment_id
        self.blocks = list(blocks)
        self.ended = False
        self.final: Optional[SegmentStats] = None

    def stats(self):
        """Return the statistics of all blocks so far."""
        return stats_of_blocks(self.blocks)

    @property
    def duration_s(self):
        """Return the time spanned so far (s)."""
        return self.blocks[-1].t_end - self.blocks[0].t_start


class StaticDetector:
    """Moving-variance still detector fed sample by sample (see the module docstring)."""

    def __init__(self, window_s=0.3, threshold_g=0.01, min_still_s=1.0, block_s=0.02,
                 saturation_g=1.9, max_gap_s=0.5):
        if window_s <= 0 or threshold_g <= 0 or min_still_s <= 0 or block_s <= 0:
            raise ValueError('window_s, threshold_g, min_still_s and block_s must be positive')
        self.window_s = float(window_s)
        self.threshold_g = float(threshold_g)
        self.min_still_s = float(min_still_s)
        self.block_s = float(block_s)
        self.saturation_g = float(saturation_g)
        self.max_gap_s = float(max_gap_s)
        self.rejected = 0
        self.rejected_nan = 0
        self.rejected_saturated = 0
        self.motion_std_g = float('nan')
        self._window = deque()
        self._block = None
        self._last_t = None
        self._next_id = 0
        self.segment: Optional[Segment] = None
        self.ended: List[Segment] = []

    @property
    def still(self):
        """Return whether the sensor is still now (a segment is open)."""
        return self.segment is not None

    def _break(self):
        self._block = None
        self._window.clear()
        self._end_segment(trim=False)

    def _end_segment(self, trim=True):
        seg = self.segment
        if seg is None:
            return
        self.segment = None
        blocks = seg.blocks
        if trim:
            limit = blocks[-1].t_end - self.window_s
            blocks = [b for b in blocks if b.t_end <= limit]
        seg.final = stats_of_blocks(blocks)
        seg.ended = True
        self.ended.append(seg)

    def add(self, t, accel_g):
        """
        Add one sample (``t`` in s, ``accel_g`` [3] in g); returns False if rejected.

        Segments that end are appended to :attr:`ended` (the caller pops them).
        """
        a = np.asarray(accel_g, dtype=float).reshape(3)
        t = float(t)
        if not np.all(np.isfinite(a)) or not np.isfinite(t):
            self.rejected += 1
            self.rejected_nan += 1
            return False
        if np.any(np.abs(a) >= self.saturation_g):
            self.rejected += 1
            self.rejected_saturated += 1
            self._break()
            return False
        if self._last_t is not None and (t < self._last_t or t - self._last_t > self.max_gap_s):
            self._break()
        self._last_t = t
        block = self._block
        if block is not None and t < block.t_start + self.block_s - 1e-9:
            block.count += 1
            block.total += a
            block.total_sq += a * a
            block.t_end = t
            return True
        if block is not None:
            self._close_block(block)
        self._block = Block(t, t, 1, a.copy(), a * a)
        return True

    def add_many(self, t, accel_g):
        """Add samples ``t`` (N,) and ``accel_g`` (N, 3) in order; returns how many were used."""
        used = 0
        for ti, ai in zip(np.asarray(t, dtype=float), np.asarray(accel_g, dtype=float)):
            used += bool(self.add(ti, ai))
        return used

    def flush(self):
        """Close the open block and segment (end of a recording)."""
        if self._block is not None:
            self._close_block(self._block)
            self._block = None
        self._end_segment(trim=False)

    def _close_block(self, block):
        window = self._window
        window.append(block)
        while window and window[0].t_start < block.t_end - self.window_s:
            window.popleft()
        if len(window) < 3:
            return
        means = np.array([b.mean for b in window])
        self.motion_std_g = float(np.max(np.std(means, axis=0, ddof=1)))
        if self.motion_std_g < self.threshold_g:
            if self.segment is None:
                self.segment = Segment(self._next_id, window)
                self._next_id += 1
            else:
                self.segment.blocks.append(block)
        else:
            self._end_segment(trim=True)
