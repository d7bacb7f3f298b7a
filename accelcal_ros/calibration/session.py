"""
A calibration session (pure core): feed samples, capture still positions, fit.

:class:`Calibrator` is what the ``calibration`` node and ``accelcal calibrate`` share.
Samples are raw readings in g (sensor frame) with times in s. A
:class:`~accelcal_ros.sensor.stillness.StillnessDetector` finds still dwells; with
``auto_capture`` every dwell that lasts ``min_still_s`` and whose direction is more than
``min_separation_deg`` from every captured position is captured (provisionally at
``min_still_s``, then refined with the rest of the dwell until the sensor moves).
``capture_now()`` takes the current dwell on request. After each capture
:meth:`Calibrator.progress` reports the count, the sphere coverage, the roll/pitch error
predicted from a fit of the current set, and which orientations to add.
:meth:`Calibrator.finish` runs :func:`~accelcal_ros.calibration.ellipsoid_fit.fit_ellipsoid`.

Order of calls: ``start`` -> samples / ``capture_now`` -> ``finish`` or ``cancel``. Calls
out of order raise :class:`~accelcal_ros.errors.CalibrationError` saying what to call.
"""
from dataclasses import dataclass, field
from typing import List, Optional, Sequence, Set, Tuple

from accelcal_ros.calibration.coverage import coverage_fraction, suggest_directions
from accelcal_ros.calibration.ellipsoid_fit import (check_model, fit_ellipsoid, FitResult,
                                                    parameter_count)
from accelcal_ros.errors import AccelcalError, CalibrationError
from accelcal_ros.sensor.stillness import StillnessDetector, StillnessThresholds
import numpy as np
from numpy.typing import ArrayLike


def _no_gravity(mean_g: np.ndarray) -> str:
    """
    Return why a still mean reading (g) is no gravity direction, or '' when it is one.

    Below :data:`~accelcal_ros.sensor.tilt.MIN_FORCE_G` (an all-zero reading: a stuck or
    unpowered sensor) it has no direction to capture.
    """
    from accelcal_ros.sensor.tilt import MIN_FORCE_G

    magnitude = float(np.linalg.norm(mean_g))
    if magnitude >= MIN_FORCE_G:
        return ''
    return (f'it reads |a| = {magnitude:.3f} g, below {MIN_FORCE_G:g} g: no gravity '
            'direction (a stuck, unpowered or disconnected sensor?)')


@dataclass
class CalibratorConfig:
    """Session settings; each is a parameter of the ``calibration`` node."""

    model: str = 'full'
    auto_capture: bool = True
    min_separation_deg: float = 20.0
    window_s: float = 0.3
    still_threshold_g: float = 0.01
    min_still_s: float = 1.0
    saturation_g: float = 1.9
    coverage_radius_deg: float = 40.0
    min_positions: int = 0
    """0: the model's parameter count + 1."""
    outlier_threshold: float = 6.0


@dataclass
class Capture:
    """One captured still position."""

    index: int
    mean_g: np.ndarray
    std_of_mean_g: np.ndarray
    samples: int
    duration_s: float
    automatic: bool
    segment_id: int
    final: bool = False
    blocks_seen: int = 0


@dataclass
class Progress:
    """Where a session stands (published as ``calibration/status``)."""

    active: bool
    positions: int
    coverage: float
    predicted_tilt_error_deg: Optional[float]
    needed: int
    hints: List[str] = field(default_factory=list)
    still: bool = False
    rejected_samples: int = 0
    note: str = ''

    def text(self) -> str:
        """Return a one-line readout."""
        if not self.active:
            return 'no calibration session (call calibration/start)'
        predicted = ('n/a' if self.predicted_tilt_error_deg is None
                     else f'{self.predicted_tilt_error_deg:.3f} deg')
        line = (f'{self.positions} positions (need {self.needed}), coverage '
                f'{self.coverage * 100:.0f} %, predicted roll/pitch error p95 {predicted}, '
                f'sensor {"still" if self.still else "moving"}')
        if self.hints:
            line += '; add: ' + '; '.join(self.hints)
        return line


class Calibrator:
    """A field calibration session (see the module docstring)."""

    def __init__(self, config: Optional[CalibratorConfig] = None) -> None:
        self.config = config or CalibratorConfig()
        check_model(self.config.model)
        self.active = False
        self.captures: List[Capture] = []
        self.detector = self._new_detector()
        self._close_segments: Set[int] = set()
        self._progress_cache: Optional[Progress] = None

    # -- session control ---------------------------------------------------------------
    def start(self) -> None:
        """Begin a new session; refused while one is running."""
        if self.active:
            raise CalibrationError(
                f'a calibration session is already running ({len(self.captures)} positions); '
                'call calibration/finish to fit it or calibration/cancel to discard it first')
        self.detector = self._new_detector()
        self.captures = []
        self._close_segments = set()
        self._progress_cache = None
        self.active = True

    def _new_detector(self) -> StillnessDetector:
        cfg = self.config
        return StillnessDetector(StillnessThresholds(
            window_s=cfg.window_s, accel_std_g=cfg.still_threshold_g,
            min_still_s=cfg.min_still_s, saturation_g=cfg.saturation_g))

    def cancel(self) -> int:
        """Discard the running session; refused if none is running."""
        self._require_active('cancel')
        self.active = False
        count = len(self.captures)
        self.captures = []
        return count

    def _require_active(self, what):
        if not self.active:
            raise CalibrationError(f'cannot {what}: no calibration session is running; '
                                   'call calibration/start first')

    @property
    def needed(self) -> int:
        """Return the number of positions the fit needs."""
        return max(self.config.min_positions, parameter_count(self.config.model) + 1)

    # -- samples -----------------------------------------------------------------------
    def add_samples(self, t: ArrayLike, accel_g: ArrayLike) -> List[str]:
        """
        Feed samples ``t`` (N,) in s and ``accel_g`` (N, 3) in g; returns event messages.

        Ignored (returns []) when no session runs. Events name captured positions, dwells
        too close to a captured one, and rejected (NaN/saturated) samples.
        """
        if not self.active:
            return []
        t_list = np.atleast_1d(np.asarray(t, dtype=float)).tolist()
        a_list = np.asarray(accel_g, dtype=float).reshape(-1, 3).tolist()
        events = []
        for ti, ai in zip(t_list, a_list):
            events += self.add_sample(ti, ai)
        return events

    def add_sample(self, t_s: float, accel_g: Sequence[float]) -> List[str]:
        """
        Feed one sample (``t_s`` s, ``accel_g`` [3] g, plain floats); returns event messages.

        The per-sample path of the node: no arrays are built unless something happens.
        """
        if not self.active:
            return []
        detector = self.detector
        before = detector.rejected
        detector.add(t_s, accel_g)
        events = self._handle_ended() if detector.ended else []
        seg = detector.segment
        if seg is not None and self.config.auto_capture \
                and seg.duration_s >= self.config.min_still_s:
            events += self._auto_capture(seg)
        if before == 0 and detector.rejected:
            events.append('rejected samples that are NaN or saturated (beyond '
                          f'{self.config.saturation_g:g} g); they are not used')
        return events

    def flush(self) -> List[str]:
        """End the current dwell (end of a recording); returns event messages."""
        if not self.active:
            return []
        self.detector.flush()
        return self._handle_ended()

    def _capture_for(self, segment_id):
        for cap in self.captures:
            if cap.segment_id == segment_id:
                return cap
        return None

    def _handle_ended(self):
        events = []
        for seg in self.detector.ended:
            cap = self._capture_for(seg.segment_id)
            if cap is not None and not cap.final:
                final = seg.final
                if final is not None and final.samples >= cap.samples:
                    cap.mean_g, cap.std_of_mean_g = final.accel_mean, final.accel_std_of_mean
                    cap.samples, cap.duration_s = final.samples, final.duration_s
                    self._progress_cache = None
                cap.final = True
                events.append(f'position {cap.index} done: {cap.samples} samples over '
                              f'{cap.duration_s:.1f} s')
            elif cap is None and self.config.auto_capture and seg.final is not None \
                    and seg.final.duration_s >= self.config.min_still_s:
                # A dwell that ended without being captured (e.g. flushed recording).
                events += self._auto_capture(seg, stats=seg.final)
        self.detector.ended.clear()
        return events

    def _closest(self, direction):
        if not self.captures:
            return None, 180.0
        dirs = np.array([c.mean_g / np.linalg.norm(c.mean_g) for c in self.captures])
        cosines = dirs @ direction
        k = int(np.argmax(cosines))
        return k, float(np.degrees(np.arccos(np.clip(cosines[k], -1.0, 1.0))))

    def _auto_capture(self, seg, stats=None):
        if seg.segment_id in self._close_segments:
            return []
        cap = self._capture_for(seg.segment_id)
        if cap is not None:
            if not cap.final and cap.blocks_seen != len(seg.blocks):
                cap.blocks_seen = len(seg.blocks)
                current = seg.stats()
                cap.mean_g, cap.std_of_mean_g = current.accel_mean, current.accel_std_of_mean
                cap.samples, cap.duration_s = current.samples, current.duration_s
            return []
        stats = stats or seg.stats()
        problem = _no_gravity(stats.accel_mean)
        if problem:
            self._close_segments.add(seg.segment_id)
            return [f'still, but {problem}: not captured']
        direction = stats.accel_mean / np.linalg.norm(stats.accel_mean)
        k, angle = self._closest(direction)
        if k is not None and angle <= self.config.min_separation_deg:
            self._close_segments.add(seg.segment_id)
            return [f'still, but only {angle:.0f} deg from position {k} (needs more than '
                    f'{self.config.min_separation_deg:g} deg): not captured; turn the sensor '
                    'further']
        cap = self._add_capture(stats, seg.segment_id, automatic=True)
        cap.final = seg.ended
        return [f'captured position {cap.index} automatically ({cap.samples} samples)']

    def _add_capture(self, stats, segment_id, automatic):
        cap = Capture(index=len(self.captures), mean_g=stats.accel_mean,
                      std_of_mean_g=stats.accel_std_of_mean, samples=stats.samples,
                      duration_s=stats.duration_s, automatic=automatic, segment_id=segment_id)
        self.captures.append(cap)
        self._progress_cache = None
        return cap

    def capture_now(self, min_still_s: float = 0.3) -> 'Capture':
        """
        Capture the current still dwell now; returns the :class:`Capture`.

        Refused (CalibrationError with the reason) with no session, while the sensor
        moves, when it has been still for less than ``min_still_s``, or when this dwell
        is already captured.
        """
        self._require_active('capture')
        seg = self.detector.segment
        if seg is None:
            std = self.detector.motion_std
            level = '' if not np.isfinite(std) else (
                f' (motion {std * 1e3:.1f} mg > threshold '
                f'{self.config.still_threshold_g * 1e3:.1f} mg)')
            raise CalibrationError(f'the sensor is moving{level}: hold it still and call '
                                   'calibration/capture again')
        if seg.duration_s < min_still_s:
            raise CalibrationError(f'the sensor has been still for only {seg.duration_s:.2f} s; '
                                   f'hold it still for {min_still_s:g} s and call again')
        existing = self._capture_for(seg.segment_id)
        if existing is not None:
            raise CalibrationError(f'this position is already captured as position '
                                   f'{existing.index}; turn the sensor to a new orientation')
        stats = seg.stats()
        if stats is None:   # a still segment of min_still_s holds blocks: not reached
            raise CalibrationError('no still samples yet; hold the sensor still and call again')
        problem = _no_gravity(stats.accel_mean)
        if problem:
            raise CalibrationError(f'{problem}: not captured')
        return self._add_capture(stats, seg.segment_id, automatic=False)

    # -- progress and fit --------------------------------------------------------------
    def captured_means(self) -> Tuple[np.ndarray, np.ndarray]:
        """Return the captured mean readings (K, 3) in g and their noise of the mean."""
        if not self.captures:
            return np.zeros((0, 3)), np.zeros((0, 3))
        return (np.array([c.mean_g for c in self.captures]),
                np.array([c.std_of_mean_g for c in self.captures]))

    def progress(self) -> 'Progress':
        """Return the :class:`Progress` of the session (fit of the current set cached)."""
        if not self.active:
            return Progress(False, 0, 0.0, None, self.needed)
        still = self.detector.still
        rejected = self.detector.rejected
        if self._progress_cache is not None:
            cached = self._progress_cache
            cached.still, cached.rejected_samples = still, rejected
            return cached
        means, stds = self.captured_means()
        coverage = coverage_fraction(means, self.config.coverage_radius_deg) if len(means) else 0.0
        predicted, note = None, ''
        count = parameter_count(self.config.model)
        if len(means) >= count:
            try:
                fit = fit_ellipsoid(means, stds, model=self.config.model, drop_outliers=False,
                                    holdout=False, min_positions=count)
                predicted = fit.predicted_tilt_error_deg
            except AccelcalError as exc:
                note = str(exc)
        else:
            note = f'{count - len(means)} more positions before an error can be predicted'
        done = coverage >= 0.99 and predicted is not None and predicted < 0.1 \
            and len(means) >= self.needed
        hints = [] if done else suggest_directions(means, 3)
        progress = Progress(True, len(means), coverage, predicted, self.needed,
                            hints, still, rejected, note)
        self._progress_cache = progress
        return progress

    def finish(self, drop_outliers: bool = True, holdout: bool = True,
               end: bool = True) -> FitResult:
        """
        Fit the captured positions; returns the FitResult and ends the session.

        On refusal (too few or badly spread positions) the session stays open so that
        more positions can be captured; the error says what to add. With ``end=False``
        the session stays open after a fit too (call :meth:`end` once it is saved).
        """
        self._require_active('finish')
        means, stds = self.captured_means()
        if len(means) < self.needed:
            hints = '; '.join(suggest_directions(means, 3))
            raise CalibrationError(
                f'{len(means)} positions are too few for the {self.config.model} model: '
                f'capture at least {self.needed} (e.g. add {hints})')
        result = fit_ellipsoid(means, stds, model=self.config.model,
                               drop_outliers=drop_outliers, holdout=holdout,
                               min_positions=self.needed,
                               outlier_threshold=self.config.outlier_threshold)
        if end:
            self.end()
        return result

    def end(self) -> None:
        """End the session without fitting (after a fit was saved)."""
        self.active = False
