"""
Which camera frames form a set, and when: the ``stitcher`` node's policy without ROS.

:class:`FrameSetPolicy` receives camera frames (stamps in seconds, any clock) and
attitudes (REP-103 roll/pitch of the IMU, rad) as they arrive, and :meth:`~FrameSetPolicy.poll`
returns the next :class:`FrameSet` to stitch, or ``None``:

* **Set.** The newest frame of a live camera whose stamp every other live camera matches
  within ``sync_tolerance_s`` (:class:`~accelcal_ros.rosutil.stamp_sync.StampMatcher`);
  stamps never go backwards: a set no newer than the last one is not stitched again.
* **Stall.** A camera with no frame for ``stale_timeout_s`` (wall time) is left out: its
  sector stays black and the others go on; said once when it stalls and when it is back.
* **Attitude.** Before the first attitude nothing is stitched (said once). The attitude
  of the frames' instant may still be on its way (topics are not ordered): the policy
  waits up to ``attitude_wait_s`` for one stamped at or after the frames, then takes the
  attitude at the frames' stamp (interpolated between the two around it, or the nearest
  within ``attitude_tolerance_s``) or skips the set (said once).
* **Time jumps.** A stream (camera or attitude) whose stamp moves by more than
  ``jump_threshold_s`` away from what the wall time elapsed since its previous message
  allows -- a set stamped in the future, the clock jumping back on ``ros2 bag play
  --loop`` -- resets the policy (buffers, the last set's stamp), counts the jump and says
  so; without it one future stamp would stop the stitching for good. A smaller backward
  jump heals by itself once the stamps pass the last set's (within the threshold).

Dropped input: a rejected frame (kind ``<camera>_frames``), a refused attitude
(``attitudes``) and a set skipped for want of an attitude near its stamp (``frame_sets``)
are counted; with ``on_drop(kind, reason, detail=cause)`` (the node's DropCounter) each
is handed on and the policy logs nothing of its own about them; without it each is said
once.

Times: stamps in seconds of the message clock; ``now_s`` in seconds of a monotonic wall
clock (``time.monotonic``). :class:`FrameSetWorker` owns the one thread that polls the
policy and hands the sets on. Thread-safe: frames and attitudes may be added from any
thread.
"""
from dataclasses import dataclass
import math
import threading
import time
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Type

from accelcal_ros.errors import AccelcalError
from accelcal_ros.frames import attitude_problem
from accelcal_ros.rosutil.stamp_sync import StampMatcher

JUMP_THRESHOLD_S = 2.0
"""Default time-jump threshold: stamp change minus wall time elapsed, seconds."""

UNMATCHED_REPORT_S = 2.0
"""Live cameras that never match for this long (wall time) are reported (once)."""

SETTINGS = ('sync_tolerance_s', 'stale_timeout_s', 'attitude_tolerance_s', 'attitude_wait_s')
"""Keys the policy reads from its settings mapping at every poll (seconds)."""


def _no_log(level: str, text: str) -> None:
    """Discard a log line (default logger)."""


@dataclass
class FrameSet:
    """
    One set to stitch: ``images`` in rig order (None: camera left out, sector black).

    ``stamp_s``: the newest frame stamp of the set (the panorama's stamp); ``roll_rad``,
    ``pitch_rad``: the attitude matched to it (REP-103, IMU).
    """

    stamp_s: float
    images: List[Any]
    roll_rad: float
    pitch_rad: float


@dataclass
class CameraState:
    """What :meth:`FrameSetPolicy.cameras` reports per camera (for diagnostics)."""

    label: str
    received: int
    rejected: int
    age_s: Optional[float]
    stalled: bool
    reject_reason: str


class FrameSetPolicy:
    """
    The frame-set policy; ``settings[key]`` for every key of :data:`SETTINGS` (seconds).

    ``labels``: one name per camera used in log lines (e.g. ``"cam0 (cam0/image_raw)"``);
    ``log(level, text)`` with level ``'info'`` or ``'warning'``; ``on_drop(kind, reason,
    detail=...)`` receives every dropped input (see the module; ``detail``: the cause, for
    a log throttle of its own); ``names``: the cameras' short names for
    the kinds (default: the labels).
    """

    def __init__(self, labels: Sequence[str], settings: Mapping[str, float],
                 log: Callable[[str, str], None] = _no_log, depth: int = 4,
                 jump_threshold_s: float = JUMP_THRESHOLD_S,
                 on_drop: Optional[Callable[..., Any]] = None,
                 names: Optional[Sequence[str]] = None):
        self.labels = list(labels)
        self.names = list(names) if names is not None else list(self.labels)
        self.on_drop = on_drop
        self.settings = settings
        self.log = log
        self.jump_threshold_s = float(jump_threshold_s)
        n = len(self.labels)
        self._frames = StampMatcher(list(range(n)), depth=depth)
        self._attitudes = StampMatcher(['attitude'], depth=500)
        self._lock = threading.RLock()
        self._last_receive: List[Optional[float]] = [None] * n
        self._received = [0] * n
        self._rejected = [0] * n
        self._reject_reason = [''] * n
        self._stalled = [False] * n
        self._previous: Dict[Any, Tuple[float, float]] = {}
        self._warned: set = set()
        self._last_published = -math.inf
        self._last_tried = -math.inf
        self._unmatched_since: Optional[float] = None
        self._waiting: Optional[Tuple[float, float]] = None
        self.retry = False
        """True when :meth:`poll` waits for an attitude: poll again soon (a few ms)."""
        self.status = 'waiting for camera frames'
        """One line on the state of the stitching (``'publishing'`` when all is well)."""
        self.time_jumps = 0
        """Time jumps detected so far (each reset the policy)."""
        self.rejected_attitudes = 0
        """Attitudes refused so far (not finite, or outside roll +-pi, pitch +-pi/2)."""
        self.last_jump = ''
        """The latest time jump: stream, size and stamp ('' before the first)."""
        self._last_jump_log = -math.inf

    # -- helpers --------------------------------------------------------------------------
    def _warn_once(self, key: Any, text: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            self.log('warning', text)

    def _dropped(self, kind: str, key: Any, text: str) -> None:
        """Hand a dropped input to ``on_drop``, or say it once (``key``)."""
        if self.on_drop is not None:
            self.on_drop(kind, text, detail=str(key))
        else:
            self._warn_once(key, f'{text} (reported once)')

    def _check_jump(self, stream: Any, label: str, stamp_s: float, now_s: float) -> None:
        """Reset everything when ``stream`` jumps in time (caller holds the lock)."""
        previous = self._previous.get(stream)
        if previous is not None:
            jump_s = (stamp_s - previous[0]) - (now_s - previous[1])
            if abs(jump_s) > self.jump_threshold_s:
                self._reset()
                self.time_jumps += 1
                self.last_jump = (f'{jump_s:+.3f} s on {label} (stamp {previous[0]:.3f} -> '
                                  f'{stamp_s:.3f})')
                self.status = f'time jump: {self.last_jump}'
                if now_s - self._last_jump_log >= 1.0:
                    self._last_jump_log = now_s
                    self.log('warning', f'time jump of {self.last_jump}: frame sets and '
                             f'attitudes dropped, starting again (jump {self.time_jumps}; '
                             'a bag replayed in a loop or a clock set)')
        self._previous[stream] = (stamp_s, now_s)

    def _reset(self) -> None:
        self._frames.clear()
        self._attitudes.clear()
        self._previous.clear()
        self._last_published = -math.inf
        self._last_tried = -math.inf
        self._unmatched_since = None
        self._waiting = None
        self._warned.discard('unmatched')

    # -- inputs ---------------------------------------------------------------------------
    def add_frame(self, index: int, stamp_s: float, image: Any, now_s: float) -> None:
        """Store camera ``index``'s frame stamped ``stamp_s``, received at ``now_s``."""
        with self._lock:
            self._check_jump(index, f'camera {self.labels[index]}', stamp_s, now_s)
            self._frames.add(index, stamp_s, image)
            self._received[index] += 1
            self._last_receive[index] = now_s

    def reject_frame(self, index: int, reason: str) -> None:
        """Count a frame of camera ``index`` that could not be used; say why once."""
        with self._lock:
            self._rejected[index] += 1
            self._reject_reason[index] = reason
        self._dropped(f'{self.names[index]}_frames', ('image', index, reason),
                      f'camera {self.labels[index]}: frame rejected: {reason}')

    def add_attitude(self, stamp_s: float, roll_rad: float, pitch_rad: float,
                     now_s: float) -> bool:
        """Store an attitude (rad); False (counted, said once) if it is not one."""
        problem = attitude_problem(roll_rad, pitch_rad)
        if problem:
            with self._lock:
                self.rejected_attitudes += 1
            self._dropped('attitudes', 'bad_attitude', f'attitude rejected: {problem}; the '
                          'last good attitude stays in use (counted in /diagnostics as '
                          'rejected_attitudes)')
            return False
        with self._lock:
            self._check_jump('attitude', 'attitude', stamp_s, now_s)
            self._attitudes.add('attitude', stamp_s, (roll_rad, pitch_rad))
        return True

    # -- state ----------------------------------------------------------------------------
    def cameras(self, now_s: float) -> List[CameraState]:
        """Return each camera's counts, frame age (s, None before the first) and stall."""
        timeout = self.settings['stale_timeout_s']
        with self._lock:
            states = []
            for i, label in enumerate(self.labels):
                last = self._last_receive[i]
                age = None if last is None else now_s - last
                states.append(CameraState(label, self._received[i], self._rejected[i], age,
                                          age is not None and age > timeout,
                                          self._reject_reason[i]))
        return states

    def _live_cameras(self, now_s: float) -> List[int]:
        timeout = self.settings['stale_timeout_s']
        live = []
        for i, last in enumerate(self._last_receive):
            if last is not None and now_s - last <= timeout:
                live.append(i)
                if self._stalled[i]:
                    self._stalled[i] = False
                    self.log('info', f'camera {self.labels[i]} is back')
            elif last is not None and not self._stalled[i]:
                self._stalled[i] = True
                self.log('warning', f'camera {self.labels[i]} stalled: no frame for '
                         f'{now_s - last:.1f} s; its sector stays black, the others go on')
        return live

    def _report_unmatched(self, candidates: List[float], live: List[int], tolerance: float,
                          now_s: float) -> None:
        """Say once when the live cameras' stamps never come within the tolerance."""
        if not candidates or candidates[0] <= self._last_published:
            return
        if self._unmatched_since is None:
            self._unmatched_since = now_s
            return
        if now_s - self._unmatched_since < UNMATCHED_REPORT_S:
            return
        newest = candidates[0]
        offsets = []
        for i in live:
            near = self._frames.nearest(newest, math.inf, keys=[i])[i]
            if near is not None and abs(near[0] - newest) > tolerance:
                offsets.append(f'{self.labels[i]} {1e3 * (near[0] - newest):+.0f} ms')
        self.status = 'no complete set of frames within sync_tolerance_s'
        self._warn_once('unmatched', 'no set of frames with stamps within sync_tolerance_s '
                        f'= {tolerance} s for {UNMATCHED_REPORT_S:g} s (offsets from the '
                        f'newest frame: {", ".join(offsets) or "none"}); trigger the '
                        'cameras together or raise sync_tolerance_s (reported once)')

    # -- the decision ---------------------------------------------------------------------
    def poll(self, now_s: float) -> Optional[FrameSet]:
        """Return the next frame set to stitch (marked as done), or None; see the module."""
        with self._lock:
            self.retry = False
            return self._poll(now_s)

    def _poll(self, now_s: float) -> Optional[FrameSet]:
        live = self._live_cameras(now_s)
        if not live:
            return None
        tolerance = self.settings['sync_tolerance_s']
        candidates = sorted({self._frames.latest_stamp(i) for i in live} - {None},
                            reverse=True)
        chosen = None
        for stamp in candidates:
            if stamp <= self._last_published or stamp <= self._last_tried:
                break
            match = self._frames.nearest(stamp, tolerance, keys=live)
            if all(match[i] is not None for i in live):
                chosen = match
                break
        if chosen is None:
            self._report_unmatched(candidates, live, tolerance, now_s)
            return None
        self._unmatched_since = None
        newest = max(m[0] for m in chosen.values())
        latest_attitude = self._attitudes.latest_stamp()
        if latest_attitude is None:
            self.status = 'no attitude yet'
            self._warn_once('no_attitude', 'no attitude received yet on "attitude" '
                            '(geometry_msgs/Vector3Stamped, x roll, y pitch, rad): '
                            'publishing nothing until one arrives')
            self._last_tried = newest
            return None
        if latest_attitude < newest - 1e-6:
            if self._waiting is None or self._waiting[0] != newest:
                self._waiting = (newest, now_s)
            if now_s - self._waiting[1] < self.settings['attitude_wait_s']:
                self.retry = True
                return None
        self._waiting = None
        tolerance_att = self.settings['attitude_tolerance_s']
        attitude = self._attitudes.interpolated('attitude', newest, tolerance_att)
        if attitude is None:
            self.status = 'no attitude near the frame stamps'
            self._dropped('frame_sets', 'attitude_gap', f'no attitude within {tolerance_att} '
                          f's of the frame stamp {newest:.3f}: frames skipped (check clocks / '
                          'the attitude node)')
            self._last_tried = newest
            return None
        self._last_published = newest
        images = [chosen[i][1] if chosen.get(i) is not None else None
                  for i in range(len(self.labels))]
        roll, pitch = attitude[1]
        return FrameSet(newest, images, roll, pitch)


class FrameSetWorker:
    """
    The one thread that polls a :class:`FrameSetPolicy` and hands sets to ``stitch``.

    Call :meth:`wake` after adding a frame or an attitude. ``stitch(frame_set)`` runs in
    this thread; an exception of the ``recoverable`` types that it raises goes to
    ``on_error(exc)`` and the thread goes on (default: bad input and numeric failures; a
    node, the process boundary, passes ``(Exception,)`` so that its thread always lives).
    :meth:`close` stops the thread. ``clock``: the policy's ``now_s`` (monotonic seconds).
    """

    def __init__(self, policy: FrameSetPolicy, stitch: Callable[[FrameSet], None],
                 on_error: Callable[[Exception], None],
                 clock: Callable[[], float] = time.monotonic, idle_s: float = 0.1,
                 retry_s: float = 0.005,
                 recoverable: Tuple[Type[Exception], ...] = (
                     AccelcalError, ValueError, ArithmeticError)):
        self.policy = policy
        self._stitch = stitch
        self._on_error = on_error
        self._recoverable = recoverable
        self._clock = clock
        self._idle_s, self._retry_s = idle_s, retry_s
        self._wake = threading.Event()
        self._stop = False
        self._thread = threading.Thread(target=self._run, name='frame_sets', daemon=True)
        self._thread.start()

    def wake(self) -> None:
        """Poll the policy now (a frame or an attitude arrived)."""
        self._wake.set()

    def _run(self) -> None:
        while not self._stop:
            self._wake.wait(timeout=self._retry_s if self.policy.retry else self._idle_s)
            self._wake.clear()
            if self._stop:
                break
            try:
                frame_set = self.policy.poll(self._clock())
                if frame_set is not None:
                    self._stitch(frame_set)
            except self._recoverable as exc:  # on_error says why; the thread goes on
                self._on_error(exc)

    def close(self, timeout_s: float = 2.0) -> None:
        """Stop the thread (waits up to ``timeout_s``)."""
        self._stop = True
        self._wake.set()
        self._thread.join(timeout=timeout_s)
