r"""
The one stillness detector: accelerometer, and gyro when present (pure core).

Used by the calibration session (still dwells), the LiDAR capture (still periods, while
streaming) and the offline static segments of a recorded log. Its thresholds are stated
once, in :class:`StillnessThresholds`.

Method. Samples (time ``t_s`` in s, acceleration in the detector's unit, gyro in rad/s)
are averaged over short blocks of ``block_s`` (20 ms), so that the detector sees the
same noise at every output data rate (the ADXL345's white noise averaged over 20 ms is
about 3 mg at 100 Hz as at 3200 Hz). The sensor is *still* while, over the blocks of the
last ``window_s`` (at least 3 blocks):

* the standard deviation of the block means is below ``accel_std_g`` on every
  accelerometer axis, and
* when every sample of those blocks has a gyro reading: the standard deviation of the
  gyro block means is below ``gyro_std_rad_s`` on every axis and the norm of their mean
  below ``gyro_rate_rad_s`` (a slow steady turn has a small spread but a mean rate).

A still *segment* runs from the start of the first still window until the window stops
being still; when motion ends it, its last ``window_s`` is trimmed (the motion that
ended it had already begun there). Invalid samples are not used and are counted: a NaN
or infinite value is skipped; a sample with any accelerometer axis at or beyond
``saturation_g`` (a shock) also ends the current segment, as motion does; a time stamp
going backwards or jumping by more than ``max_gap_s`` ends the segment (untrimmed).

Units. Thresholds are in g and rad/s. ``accel_unit_m_s2`` says what one unit of the
acceleration fed in is: :data:`~accelcal_ros.sensor.units.STANDARD_GRAVITY_M_S2` (the
default) for g, ``1.0`` for m/s^2; means and spreads come back in that unit.

API (stable):

* ``StillnessThresholds(window_s=0.3, accel_std_g=0.01, gyro_std_rad_s=0.01,
  gyro_rate_rad_s=0.05, min_still_s=1.0, block_s=0.02, saturation_g=1.9,
  max_gap_s=0.5)``: frozen dataclass, checked by :meth:`StillnessThresholds.check`.
* ``StillnessDetector(thresholds=None, accel_unit_m_s2=STANDARD_GRAVITY_M_S2)``
  (streaming): ``add(t_s, accel, gyro=None) -> bool`` (False if the sample was
  rejected), ``add_many(t_s, accel, gyro=None) -> int``, ``flush()`` (end of data),
  ``still`` (a segment is open now), ``segment`` (the open :class:`StillSegment` or
  None; ``segment.stats()`` so far), ``ended`` (list of ended :class:`StillSegment`,
  the caller pops them; ``seg.final`` holds the trimmed :class:`SegmentStats`, None
  when nothing remained), ``motion_std`` (last window's largest accelerometer spread,
  in the accel unit), ``rejected``, ``rejected_nan``, ``rejected_saturated``,
  ``samples_seen`` (the index the next sample gets).
* ``still_segments(t_s, accel, gyro=None, thresholds=None,
  accel_unit_m_s2=STANDARD_GRAVITY_M_S2, min_still_s=None) -> list[SegmentStats]``
  (offline, whole recording): the final statistics of every segment at least
  ``min_still_s`` long (default ``thresholds.min_still_s``), in time order. Sample
  ``k`` of the arrays is sample ``k`` of the stream: ``SegmentStats.start``/``stop``
  index the arrays (``[start, stop)``). Same result as feeding the arrays to
  :class:`StillnessDetector` sample by sample and flushing (tested), at a fraction of
  the cost.

:class:`SegmentStats`: ``start``, ``stop`` (sample indices), ``t_start_s``, ``t_end_s``,
``samples`` (used samples), ``accel_mean`` and ``accel_std`` (per axis, accel unit,
sample standard deviation), ``gyro_mean_rad_s`` (None without a gyro), and the
properties ``duration_s`` and ``accel_std_of_mean`` (``accel_std / sqrt(samples)``).
"""
from collections import deque
from dataclasses import dataclass
import math
from typing import Deque, List, Optional, Sequence, Tuple

from accelcal_ros.errors import InputError
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
import numpy as np
from numpy.typing import ArrayLike


@dataclass(frozen=True)
class StillnessThresholds:
    """Every threshold of the stillness detector (see the module docstring)."""

    window_s: float = 0.3
    """Length of the moving window of block means (s)."""
    accel_std_g: float = 0.01
    """Largest standard deviation of accelerometer block means in a still window (g)."""
    gyro_std_rad_s: float = 0.01
    """Largest standard deviation of gyro block means in a still window (rad/s)."""
    gyro_rate_rad_s: float = 0.05
    """Largest norm of the mean gyro rate in a still window (rad/s)."""
    min_still_s: float = 1.0
    """Shortest still segment worth using (s); applied by the callers and the offline scan."""
    block_s: float = 0.02
    """Averaging block (s)."""
    saturation_g: float = 1.9
    """A reading at or beyond this on any axis is a shock: rejected, ends the segment (g)."""
    max_gap_s: float = 0.5
    """A larger gap between stamps ends the segment (the sensor may have moved unseen; s)."""

    def check(self) -> None:
        """Raise InputError naming the first threshold that is not a positive number."""
        for name in ('window_s', 'accel_std_g', 'gyro_std_rad_s', 'gyro_rate_rad_s',
                     'min_still_s', 'block_s', 'saturation_g', 'max_gap_s'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise InputError(f'stillness threshold {name} must be a positive number, '
                                 f'got {value!r}')


@dataclass
class SegmentStats:
    """Statistics of a still segment (accelerations in the detector's unit)."""

    start: int
    stop: int
    t_start_s: float
    t_end_s: float
    samples: int
    accel_mean: np.ndarray
    accel_std: np.ndarray
    gyro_mean_rad_s: Optional[np.ndarray] = None

    @property
    def duration_s(self) -> float:
        """Return the time spanned by the segment (s)."""
        return self.t_end_s - self.t_start_s

    @property
    def accel_std_of_mean(self) -> np.ndarray:
        """Return the standard deviation of the mean, ``std / sqrt(N)``."""
        return self.accel_std / math.sqrt(max(self.samples, 1))


class _Block:
    """Sums of the samples of one averaging block (plain floats: no per-sample arrays)."""

    __slots__ = ('i_start', 'i_stop', 't_start', 't_end', 'count', 'sx', 'sy', 'sz',
                 'qx', 'qy', 'qz', 'gyro_count', 'gx', 'gy', 'gz')

    def __init__(self, index, t, ax, ay, az):
        self.i_start = index
        self.i_stop = index + 1
        self.t_start = self.t_end = t
        self.count = 1
        self.sx, self.sy, self.sz = ax, ay, az
        self.qx, self.qy, self.qz = ax * ax, ay * ay, az * az
        self.gyro_count = 0
        self.gx = self.gy = self.gz = 0.0

    def mean(self) -> Tuple[float, float, float]:
        n = self.count
        return (self.sx / n, self.sy / n, self.sz / n)

    def gyro_mean(self) -> Tuple[float, float, float]:
        n = self.gyro_count
        return (self.gx / n, self.gy / n, self.gz / n)


def _stats_of_blocks(blocks) -> Optional[SegmentStats]:
    if not blocks:
        return None
    count = sum(b.count for b in blocks)
    total = np.array([[b.sx, b.sy, b.sz] for b in blocks]).sum(axis=0)
    total_sq = np.array([[b.qx, b.qy, b.qz] for b in blocks]).sum(axis=0)
    mean = total / count
    var = (total_sq - count * mean * mean) / max(count - 1, 1)
    gyro = None
    gyro_count = sum(b.gyro_count for b in blocks)
    if gyro_count == count:
        gyro = np.array([[b.gx, b.gy, b.gz] for b in blocks]).sum(axis=0) / count
    return SegmentStats(blocks[0].i_start, blocks[-1].i_stop, blocks[0].t_start,
                        blocks[-1].t_end, count, mean, np.sqrt(np.clip(var, 0.0, None)),
                        gyro)


class StillSegment:
    """One still segment being built: its blocks, an id, and whether it has ended."""

    def __init__(self, segment_id: int, blocks: Sequence[_Block]) -> None:
        self.segment_id = segment_id
        self.blocks = list(blocks)
        self.ended = False
        self.final: Optional[SegmentStats] = None

    def stats(self) -> Optional[SegmentStats]:
        """Return the statistics of all blocks so far (untrimmed)."""
        return _stats_of_blocks(self.blocks)

    @property
    def t_start_s(self) -> float:
        """Return the time of the segment's first sample (s)."""
        return self.blocks[0].t_start

    @property
    def duration_s(self) -> float:
        """Return the time spanned so far (s)."""
        return self.blocks[-1].t_end - self.blocks[0].t_start


class StillnessDetector:
    """Streaming stillness detector fed sample by sample (see the module docstring)."""

    def __init__(self, thresholds: Optional[StillnessThresholds] = None,
                 accel_unit_m_s2: float = STANDARD_GRAVITY_M_S2) -> None:
        self.thresholds = thresholds or StillnessThresholds()
        self.thresholds.check()
        if not (math.isfinite(accel_unit_m_s2) and accel_unit_m_s2 > 0):
            raise InputError(f'accel_unit_m_s2 must be positive, got {accel_unit_m_s2!r}')
        th = self.thresholds
        per_g = STANDARD_GRAVITY_M_S2 / accel_unit_m_s2
        self._accel_std = th.accel_std_g * per_g
        self._saturation = th.saturation_g * per_g
        self.rejected = 0
        self.rejected_nan = 0
        self.rejected_saturated = 0
        self.samples_seen = 0
        self.motion_std = float('nan')
        self._window: Deque[_Block] = deque()
        self._block: Optional[_Block] = None
        self._last_t: Optional[float] = None
        self._next_id = 0
        self.segment: Optional[StillSegment] = None
        self.ended: List[StillSegment] = []

    @property
    def still(self) -> bool:
        """Return whether the sensor is still now (a segment is open)."""
        return self.segment is not None

    def add(self, t_s: float, accel: Sequence[float],
            gyro: Optional[Sequence[float]] = None) -> bool:
        """
        Add one sample (``t_s`` s, ``accel`` [3], ``gyro`` [3] rad/s or None).

        Returns False if the sample was rejected (NaN, saturated). Segments that end are
        appended to :attr:`ended`.
        """
        index = self.samples_seen
        self.samples_seen = index + 1
        t = float(t_s)
        ax, ay, az = float(accel[0]), float(accel[1]), float(accel[2])
        if gyro is not None:
            gx, gy, gz = float(gyro[0]), float(gyro[1]), float(gyro[2])
            finite = math.isfinite(gx + gy + gz)
        else:
            finite = True
        if not (finite and math.isfinite(ax + ay + az) and math.isfinite(t)):
            self.rejected += 1
            self.rejected_nan += 1
            return False
        sat = self._saturation
        if abs(ax) >= sat or abs(ay) >= sat or abs(az) >= sat:
            self.rejected += 1
            self.rejected_saturated += 1
            self._break()
            return False
        last = self._last_t
        if last is not None and (t < last or t - last > self.thresholds.max_gap_s):
            self._break()
        self._last_t = t
        block = self._block
        if block is not None and t < block.t_start + self.thresholds.block_s - 1e-9:
            block.count += 1
            block.i_stop = index + 1
            block.sx += ax
            block.sy += ay
            block.sz += az
            block.qx += ax * ax
            block.qy += ay * ay
            block.qz += az * az
            block.t_end = t
        else:
            if block is not None:
                self._close_block(block)
            block = self._block = _Block(index, t, ax, ay, az)
        if gyro is not None:
            block.gyro_count += 1
            block.gx += gx
            block.gy += gy
            block.gz += gz
        return True

    def add_many(self, t_s: ArrayLike, accel: ArrayLike,
                 gyro: Optional[ArrayLike] = None) -> int:
        """Add samples ``t_s`` (N,), ``accel`` (N, 3), ``gyro`` (N, 3) or None in order."""
        t_list = np.asarray(t_s, dtype=float).reshape(-1).tolist()
        a_list = np.asarray(accel, dtype=float).reshape(-1, 3).tolist()
        g_list = [None] * len(t_list) if gyro is None else \
            np.asarray(gyro, dtype=float).reshape(-1, 3).tolist()
        used = 0
        for ti, ai, gi in zip(t_list, a_list, g_list):
            used += self.add(ti, ai, gi)
        return used

    def flush(self) -> None:
        """Close the open block and segment (end of a recording)."""
        if self._block is not None:
            self._close_block(self._block)
            self._block = None
        self._end_segment(trim=False)

    def _break(self) -> None:
        self._block = None
        self._window.clear()
        self._end_segment(trim=False)

    def _end_segment(self, trim: bool = True) -> None:
        seg = self.segment
        if seg is None:
            return
        self.segment = None
        blocks = seg.blocks
        if trim:
            limit = blocks[-1].t_end - self.thresholds.window_s
            blocks = [b for b in blocks if b.t_end <= limit]
        seg.final = _stats_of_blocks(blocks)
        seg.ended = True
        self.ended.append(seg)

    def _window_still(self, window) -> bool:
        means = np.array([b.mean() for b in window])
        self.motion_std = float(np.max(np.std(means, axis=0, ddof=1)))
        if not self.motion_std < self._accel_std:
            return False
        if any(b.gyro_count != b.count for b in window):
            return True
        th = self.thresholds
        gyro = np.array([b.gyro_mean() for b in window])
        return bool(np.max(np.std(gyro, axis=0, ddof=1)) < th.gyro_std_rad_s
                    and np.linalg.norm(gyro.mean(axis=0)) < th.gyro_rate_rad_s)

    def _close_block(self, block: _Block) -> None:
        window = self._window
        window.append(block)
        while window and window[0].t_start < block.t_end - self.thresholds.window_s:
            window.popleft()
        if len(window) < 3:
            return
        if self._window_still(window):
            if self.segment is None:
                self.segment = StillSegment(self._next_id, window)
                self._next_id += 1
            else:
                self.segment.blocks.append(block)
        else:
            self._end_segment(trim=True)


def still_segments(t_s: ArrayLike, accel: ArrayLike, gyro: Optional[ArrayLike] = None,
                   thresholds: Optional[StillnessThresholds] = None,
                   accel_unit_m_s2: float = STANDARD_GRAVITY_M_S2,
                   min_still_s: Optional[float] = None) -> List[SegmentStats]:
    """
    Return the still segments of a whole recording (see the module docstring).

    ``t_s`` (N,) s, ``accel`` (N, 3) in units of ``accel_unit_m_s2``, ``gyro`` (N, 3)
    rad/s or None. Blocks are summed with numpy; only the window logic runs per block.
    """
    det = StillnessDetector(thresholds, accel_unit_m_s2)
    th = det.thresholds
    min_still_s = th.min_still_s if min_still_s is None else float(min_still_s)
    t = np.asarray(t_s, dtype=float).reshape(-1)
    a = np.asarray(accel, dtype=float).reshape(-1, 3)
    if a.shape[0] != t.size:
        raise InputError(f'{t.size} times for {a.shape[0]} accelerometer samples')
    g = None
    if gyro is not None:
        g = np.asarray(gyro, dtype=float).reshape(-1, 3)
        if g.shape[0] != t.size:
            raise InputError(f'{t.size} times for {g.shape[0]} gyro samples')
    finite = np.isfinite(t) & np.all(np.isfinite(a), axis=1)
    if g is not None:
        finite &= np.all(np.isfinite(g), axis=1)
    saturated = finite & np.any(np.abs(a) >= det._saturation, axis=1)
    used = np.flatnonzero(finite & ~saturated)
    # Block starts and breaks, exactly as add() decides them (a light loop over floats).
    block_of = np.empty(used.size, dtype=np.int64)
    breaks = set()
    sat_before = np.cumsum(saturated)
    t_used = t[used].tolist()
    sat_used = sat_before[used].tolist()
    block_s, max_gap_s = th.block_s - 1e-9, th.max_gap_s
    block, start, last_t, last_sat = -1, -math.inf, None, 0
    for k, (tk, sk) in enumerate(zip(t_used, sat_used)):
        broken = sk != last_sat or (last_t is not None
                                    and (tk < last_t or tk - last_t > max_gap_s))
        if broken or tk >= start + block_s:
            block += 1
            start = tk
            if broken:
                breaks.add(block)
        block_of[k] = block
        last_t, last_sat = tk, sk
    segments: List[SegmentStats] = []
    if used.size:
        first = np.flatnonzero(np.diff(np.concatenate([[-1], block_of])) != 0)
        idx = used[first]
        sums = np.add.reduceat(a[used], first, axis=0)
        sq = np.add.reduceat(a[used] ** 2, first, axis=0)
        counts = np.diff(np.concatenate([first, [used.size]]))
        last_idx = used[np.concatenate([first[1:], [used.size]]) - 1]
        t_first, t_last = t[idx], t[last_idx]
        gsum = None if g is None else np.add.reduceat(g[used], first, axis=0)
        for b in range(first.size):
            if b in breaks:
                det._break()
            if b + 1 in breaks:
                continue   # add() drops the block a break interrupts
            blk = _Block(int(idx[b]), float(t_first[b]), *sums[b].tolist())
            blk.qx, blk.qy, blk.qz = sq[b].tolist()
            blk.count = int(counts[b])
            blk.i_stop = int(last_idx[b]) + 1
            blk.t_end = float(t_last[b])
            if gsum is not None:
                blk.gyro_count = blk.count
                blk.gx, blk.gy, blk.gz = gsum[b].tolist()
            det._close_block(blk)
            if det.ended:
                segments += [s.final for s in det.ended if s.final is not None]
                det.ended.clear()
    det.flush()
    segments += [s.final for s in det.ended if s.final is not None]
    return [s for s in segments if s.duration_s >= min_still_s]
