r"""
The gyro bias from still moments: a weighted line with a drift prior (pure core).

:class:`GyroBiasEstimator` takes the means of short blocks of gyro samples (20 ms) that a
stillness detector has passed (:class:`~accelcal_ros.sensor.tilt_filter.AttitudeFilter`
feeds it) and returns the bias at the newest block:

* within one still period (blocks no further apart than ``gap_s``, or than
  :data:`JOIN_S` while no new stillness has begun: a gap the caller made, such as
  odometry's speed noise reading 'moving' for a sample at a stop, does not restart the
  line, whose restart kept the old level as a prior and lagged behind a drift), per
  axis, the least-squares line through the block means, weighted by their sample counts and
  forgotten with the time constant ``memory_s``; the per-sample noise comes from the
  blocks' own scatter about that line, so the same code is right at 100 and 800 Hz;
* the line's slope is shrunk towards zero by its prior, a drift of about
  ``drift_rad_s2`` (ridge regression: ``slope * D^2 / (D^2 + var(slope))``): a bias that
  drifts while the platform stands (a gyro warming up: the ITG-3205's zero-rate output
  moves by up to 40 deg/s over -40..85 deg C) is followed, a constant one is averaged;
* the previous still period's estimate is combined by inverse variance, its variance
  grown by ``(drift_rad_s2 * elapsed)^2``.
* when the stillness ends, the blocks of its last detector window (0.3 s, where the
  motion may have begun) are dropped; with ``carry`` (:meth:`~GyroBiasEstimator.feed`)
  the line is carried over them to the end of the stillness (its slope times their
  span): a drift is then not 0.3 s behind. The filter carries it only without odometry
  (with odometry the accelerometer stays trusted through manoeuvres and its integral
  term corrects the bias; the slope's noise carried along made + both at 800 Hz worse:
  median p95 0.148 -> 0.153 deg over drive seeds 0-15).

Why it matters: while the platform accelerates, the tilt runs mostly on the gyro, and
a bias error ``e`` (rad/s) tilts the estimate by ``e t`` over a manoeuvre of ``t`` s
(0.05 deg/s over a 10 s turn: 0.5 deg). With the ITG-3205's 0.38 deg/s noise per
100 Hz sample, 4 s of stillness give about 0.02 deg/s (constant bias) to 0.04 deg/s (a
drift followed); the filter's integral term corrects it further while moving.
"""
from collections import deque
import math
from typing import Deque, List, Optional, Sequence, Tuple

from accelcal_ros.sensor.stillness import StillnessThresholds


JOIN_S = 1.0
"""A gap in a still line's blocks up to this long (s) continues the line when no new
stillness began in it (the detector stayed still: the gap is a condition of the caller's,
such as odometry's speed noise reading 'moving' for one sample)."""


class GyroBiasEstimator:
    """Bias (rad/s, body frame) from the block means of still moments (see the module)."""

    def __init__(self, memory_s: float = 30.0, drift_rad_s2: float = 2.0e-4,
                 gap_s: float = 0.1) -> None:
        self.memory_s = float(memory_s)
        self.drift_rad_s2 = float(drift_rad_s2)
        self.gap_s = float(gap_s)
        self.bias: Tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.variance = math.inf
        """Variance of :attr:`bias` per axis ((rad/s)^2; inf: none learnt yet)."""
        self.time = -math.inf
        """Time of the newest block used (s)."""
        self.blocks = 0
        self._run: List = []
        self._eval_t = 0.0
        self._n_last = 1.0
        self._carried = True
        self.turning = False
        """Whether the current still line turns (no rest: its blocks are not learnt)."""
        self.rest_due = -math.inf
        """When the still line's next verdict is due (s; one per 20 ms block)."""
        self._proven = False
        self._since = -math.inf
        self.restart()

    def restart(self) -> None:
        """Forget the block being averaged and those not yet committed (a restart)."""
        self._block: Optional[list] = None
        self._pending: Deque[Tuple[float, float, float, float, float, int]] = deque()

    def feed(self, stamp: float, gyro: Sequence[float], thresholds: StillnessThresholds,
             still: bool, carry: bool = True) -> None:
        """
        Average a gyro sample into 20 ms blocks; add those a still window has passed.

        ``still``: whether the sample may be used now (the detector says still, and the
        caller's conditions); a block enters only once the detector's window after it
        has been still too (the start of a motion never enters); ``carry``: whether the
        line is carried over those dropped blocks when the stillness ends (see the module).
        """
        block = self._block
        if block is None or stamp >= block[0] + thresholds.block_s or stamp < block[0]:
            if block is not None and block[4] > 0:
                n = block[4]
                self._pending.append((block[0], block[5], block[1] / n, block[2] / n,
                                      block[3] / n, n))
            block = self._block = [stamp, 0.0, 0.0, 0.0, 0, stamp]
            pending = self._pending
            if not still:
                if pending and carry and self._run and not self._carried:
                    # the stillness's last window never enters: the line carried over it
                    span = pending[-1][1] - self.time
                    if span > 0.0:
                        b, v = self.bias, self._slopes
                        self.bias = (b[0] + v[0] * span, b[1] + v[1] * span, b[2] + v[2] * span)
                        self.time = self.time + span
                    self._carried = True
                pending.clear()
            else:
                limit = stamp - thresholds.window_s
                while pending and pending[0][1] < limit:
                    item = pending.popleft()
                    self.add(item[0], item[1], (item[2], item[3], item[4]), item[5])
        block[1] += gyro[0]
        block[2] += gyro[1]
        block[3] += gyro[2]
        block[4] += 1
        block[5] = stamp

    def still_started(self, since: float) -> None:
        """Start a still line (the stillness since ``since``, s): nothing shown yet."""
        self.turning = self._proven = False
        self._since = since
        self.rest_due = -math.inf

    def rest(self, due: float, verdict: Tuple[bool, bool]) -> None:
        """Take a still line's verdict (turning, shown at rest; next due at ``due``, s)."""
        self.rest_due = due
        if verdict[0] and not self.turning:
            self.discard()
        self.turning = verdict[0]
        self._proven = self._proven or verdict[1]

    def still_ended(self) -> None:
        """End the still line: forget what it taught unless it was shown at rest."""
        if not self._proven:
            self.discard()

    def discard(self) -> None:
        """Forget what the current stillness taught (it was no rest after all)."""
        run = self._run
        if run and run[0] >= self._since:
            self.bias, self.variance, self.time = run[2], run[3], run[4]
            self._run = []
            if not math.isfinite(self.variance):   # nothing learnt before it
                self.blocks = 0
        self._pending.clear()
        self._carried = True

    def adjust(self, bias: Tuple[float, float, float]) -> None:
        """Replace the estimate (e.g. by an integral correction while moving)."""
        self.bias = bias

    def add(self, t_start: float, t_end: float, mean: Tuple[float, float, float],
            count: int, prior: Optional[list] = None) -> None:
        """Add the mean rate of ``count`` samples from ``t_start`` to ``t_end`` (s)."""
        t = 0.5 * (t_start + t_end)
        n = float(max(1, count))
        run = self._run
        gap = t - run[1] - (t_end - t_start) if run else 0.0
        if not run or t < run[1] or (gap > self.gap_s and not (
                gap <= JOIN_S and run[0] >= self._since)):
            if prior is None:
                prior_var = self.variance
                if math.isfinite(prior_var):
                    prior_var += (self.drift_rad_s2 * max(0.0, t - self.time)) ** 2
                prior = [self.bias, prior_var, self.time]
            # t0, last t, prior bias, prior variance, its time, sums: w, wt, wtt, then
            # per axis wy, wty, wyy
            run = self._run = [t, t, prior[0], prior[1], prior[2], [0.0, 0.0, 0.0],
                               [[0.0] * 3 for _ in range(3)]]
        forget = math.exp(-(t - run[1]) / self.memory_s)
        run[1] = t
        x = t - run[0]
        s = run[5]
        s[0] = s[0] * forget + n
        s[1] = s[1] * forget + n * x
        s[2] = s[2] * forget + n * x * x
        for k, y in enumerate(mean):
            a = run[6][k]
            a[0] = a[0] * forget + n * y
            a[1] = a[1] * forget + n * x * y
            a[2] = a[2] * forget + n * y * y
        self.blocks += 1
        self._carried = False
        self.time = t_end
        self._eval_t = x
        self._n_last = n
        self._estimate()

    def _estimate(self) -> None:
        run = self._run
        x = self._eval_t
        w, wt, wtt = run[5]
        mean_t = wt / w
        sxx = wtt - wt * wt / w
        means, slopes_raw, resid = [], [], 0.0
        for a in run[6]:
            sxy = a[1] - wt * a[0] / w
            syy = a[2] - a[0] * a[0] / w
            means.append(a[0] / w)
            slopes_raw.append(sxy / sxx if sxx > 1e-12 else 0.0)
            resid += max(0.0, syy - (sxy * sxy / sxx if sxx > 1e-12 else 0.0))
        blocks = w / self._n_last   # effective number of blocks (forgetting included)
        if blocks < 3:
            sample_var = math.radians(1.0) ** 2 * self._n_last   # no scatter yet: loose
        else:
            # each block's weighted squared residual is one sample's variance
            sample_var = resid / 3.0 / (blocks - 2)
        var_mean = sample_var / w
        # the slope, shrunk towards 0 by its prior (a drift of about drift_rad_s2)
        var_s = sample_var / sxx if sxx > 1e-12 else math.inf
        prior_s = self.drift_rad_s2 ** 2
        shrink = prior_s / (prior_s + var_s) if math.isfinite(var_s) else 0.0
        slopes = [v * shrink for v in slopes_raw]
        self._slopes = slopes
        lever = (x - mean_t) ** 2
        levels = [m + v * (x - mean_t) for m, v in zip(means, slopes)]
        var_level = var_mean + lever * (1.0 - shrink) ** 2 * prior_s
        if shrink > 0.0:
            var_level += lever * shrink * shrink * var_s
        prior, prior_var = run[2], run[3]
        if math.isfinite(prior_var) and prior_var > 0.0:
            g = var_level / (var_level + prior_var)
            self.bias = tuple(m + g * (p - m) for m, p in zip(levels, prior))  # type: ignore
            self.variance = var_level * (1.0 - g)
        else:
            self.bias = (levels[0], levels[1], levels[2])
            self.variance = var_level


def horizontal_error(fx: float, fy: float, fz: float, vx: float, vy: float, vz: float,
                     g_scale: float, min_g: float, full_g: float
                     ) -> Optional[Tuple[float, float, float, float]]:
    """
    Return the error of the up estimate ``v`` along the horizontal acceleration, and weight.

    A vehicle accelerates horizontally: the specific force ``f`` along the true up is
    ``g_scale`` (1 g) whatever it does. Its excess along the estimate is ``-h . du``
    (``h``: the part of ``f`` across ``v``; ``du``: the estimate's error), so
    ``du = -excess h / |h|^2`` along ``h``. The weight grows with ``|h|^2`` up to 1 at
    ``full_g`` (the information against vibration and noise); None below ``min_g``.
    """
    along = fx * vx + fy * vy + fz * vz
    hx, hy, hz = fx - along * vx, fy - along * vy, fz - along * vz
    h2 = hx * hx + hy * hy + hz * hz
    if h2 < min_g * min_g:
        return None
    c = -(along - g_scale) / h2
    return c * hx, c * hy, c * hz, min(1.0, h2 / (full_g * full_g))
