"""
A small pool of threads that decodes camera frames off the executor thread.

Image nodes receive a frame per camera in the executor's callback; decoding a JPEG there
(12 ms for 1280x960) would serialize the cameras. :class:`DecodePool` runs the jobs in
threads instead (OpenCV releases the GIL while it decodes, so the cameras' decodes run in
parallel), with two rules a camera stream needs:

* **per key in order**: jobs of one key (a camera) run one after the other, in the order
  submitted, so frames of a camera never overtake each other;
* **newest only**: while a key's job runs, only its newest waiting job is kept; an older
  waiting one is dropped (counted in :attr:`DecodePool.replaced` and handed to
  ``on_replace(key)``, outside the pool's lock), as a keep-last queue of depth 1 does.
  A slow decoder costs frames, never a growing queue or latency.

A job that raises goes to ``on_error(key, exc)``; the pool goes on. Pure Python (no
rclpy): used by :mod:`accelcal_ros.rosutil.image_input` for the stitcher and ``p2p`` and
meant for any node that takes compressed frames.
"""
from collections import deque
from concurrent.futures import ThreadPoolExecutor
import threading
import time
from typing import Any, Callable, Deque, Dict, Hashable, Optional, Set, Tuple


def _no_error(key: Hashable, exc: BaseException) -> None:
    """Drop the error (default handler: the caller gave none)."""


class DecodePool:
    """``workers`` threads; per key the newest job only, in order (see the module)."""

    def __init__(self, workers: int, name: str = 'decode',
                 on_error: Callable[[Hashable, BaseException], None] = _no_error,
                 timing_window: int = 100,
                 on_replace: Optional[Callable[[Hashable], Any]] = None):
        self._executor = ThreadPoolExecutor(max_workers=max(1, int(workers)),
                                            thread_name_prefix=name)
        self._on_error = on_error
        self._on_replace = on_replace
        self._lock = threading.Lock()
        self._waiting: Dict[Hashable, Tuple[Callable[..., Any], tuple]] = {}
        self._running: Set[Hashable] = set()
        self._durations: Deque[float] = deque(maxlen=timing_window)
        self._closed = False
        self.done = 0
        """Jobs run to the end (also those that raised)."""
        self.replaced = 0
        """Jobs dropped before they ran because a newer one of their key came."""

    def submit(self, key: Hashable, func: Callable[..., Any], *args: Any) -> None:
        """Run ``func(*args)`` in the pool after ``key``'s running job; replaces a waiting one."""
        with self._lock:
            if self._closed:
                return
            replaced = key in self._waiting
            if replaced:
                self.replaced += 1
            self._waiting[key] = (func, args)
            start = key not in self._running
            if start:
                self._running.add(key)
        if replaced and self._on_replace is not None:
            self._on_replace(key)
        if start:
            self._executor.submit(self._drain, key)

    def _drain(self, key: Hashable) -> None:
        while True:
            with self._lock:
                job = self._waiting.pop(key, None)
                if job is None or self._closed:
                    self._running.discard(key)
                    return
            func, args = job
            start = time.perf_counter()
            try:
                func(*args)
            except Exception as exc:  # the thread serves every key: report and go on
                self._on_error(key, exc)
            with self._lock:
                self._durations.append(time.perf_counter() - start)
                self.done += 1

    def mean_job_s(self) -> Optional[float]:
        """Return the mean duration of the recent jobs (seconds); None before the first."""
        with self._lock:
            return sum(self._durations) / len(self._durations) if self._durations else None

    def idle(self) -> bool:
        """Return True when no job runs or waits."""
        with self._lock:
            return not self._running and not self._waiting

    def close(self, wait: bool = True) -> None:
        """Drop the waiting jobs and stop the threads (``wait``: let running jobs end)."""
        with self._lock:
            self._closed = True
            self._waiting.clear()
        self._executor.shutdown(wait=wait)
