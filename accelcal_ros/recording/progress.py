"""
A progress bar on stderr when stderr is a terminal; silent otherwise (pipes, logs, CI).

``Progress(total, label)`` counts units (messages, bytes, frames); ``update(n)`` redraws
at most every ``min_interval_s``; ``close()`` ends the line. ``track(items, label)`` wraps
a loop: ``for item in track(items, 'trials'):`` counts one unit per item; ``clear()``
erases a drawn bar. ``ACCELCAL_PROGRESS=0`` turns it off and ``=1`` forces it on (for
tests of the drawing).
"""
import os
import sys
import time
from typing import Iterable, Iterator, Optional, TextIO, TypeVar
import weakref

Item = TypeVar('Item')


def progress_enabled(stream: Optional[TextIO] = None) -> bool:
    """Return True when a bar should be drawn on ``stream`` (default stderr)."""
    forced = os.environ.get('ACCELCAL_PROGRESS', '')
    if forced in ('0', '1'):
        return forced == '1'
    stream = sys.stderr if stream is None else stream
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


_OPEN_BARS: 'weakref.WeakSet[Progress]' = weakref.WeakSet()
"""Bars drawn and not closed (nor dropped) yet: one opened meanwhile stays silent."""


class Progress:
    """
    Count ``total`` units (0: unknown) and draw ``label [####....] 42% n/total`` lines.

    Only the outermost open bar is drawn: one opened while another is open (a boresight
    inside a study's trial loop) counts silently.
    """

    def __init__(self, total: int, label: str, stream: Optional[TextIO] = None,
                 min_interval_s: float = 0.2, width: int = 30):
        self.total = max(int(total), 0)
        self.label = label
        self.count = 0
        self.stream = sys.stderr if stream is None else stream
        self.enabled = progress_enabled(self.stream) and not _OPEN_BARS
        if self.enabled:
            _OPEN_BARS.add(self)
        self.min_interval_s = min_interval_s
        self.width = width
        self._start = time.monotonic()
        self._last = 0.0
        self._drawn = False

    def update(self, n: int = 1) -> None:
        """Add ``n`` units; redraw when enough time passed."""
        self.count += n
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self._last >= self.min_interval_s:
            self._last = now
            self._draw(now)

    def _draw(self, now: float) -> None:
        elapsed = max(now - self._start, 1e-9)
        rate = self.count / elapsed
        if self.total:
            frac = min(self.count / self.total, 1.0)
            filled = int(round(frac * self.width))
            bar = '#' * filled + '.' * (self.width - filled)
            text = (f'\r{self.label} [{bar}] {frac * 100:3.0f}% {self.count}/{self.total} '
                    f'({rate:.0f}/s)')
        else:
            text = f'\r{self.label} {self.count} ({rate:.0f}/s)'
        self.stream.write(text)
        self.stream.flush()
        self._drawn = True

    def clear(self) -> None:
        """Erase the drawn bar (before other output); the next update redraws it."""
        if self.enabled and self._drawn:
            self.stream.write('\r\x1b[K')
            self.stream.flush()
            self._drawn = False
            self._last = 0.0

    def close(self, erase: bool = False) -> None:
        """Draw the final state and end the line, or erase the bar (nothing when disabled)."""
        if self.enabled:
            if erase:
                self.clear()
            else:
                self._draw(time.monotonic())
                self.stream.write('\n')
                self.stream.flush()
            self.enabled = False
            _OPEN_BARS.discard(self)

    def __enter__(self):
        """Use as a context manager: ``close()`` on exit."""
        return self

    def __exit__(self, *exc):
        """End the line."""
        self.close()
        return False


def track(items: Iterable[Item], label: str, total: Optional[int] = None,
          stream: Optional[TextIO] = None) -> Iterator[Item]:
    """
    Yield ``items``, drawing a :class:`Progress` bar of one unit per item.

    ``total`` defaults to ``len(items)`` when it has one (0, a count without a bar,
    otherwise). The line is ended when the loop ends, also on break or an exception.
    """
    if total is None:
        total = len(items) if hasattr(items, '__len__') else 0  # type: ignore[arg-type]
    progress = Progress(total, label, stream)
    saved = sys.stdout
    if progress.enabled:   # lines printed by the loop erase the bar first
        sys.stdout = _ClearingStream(saved, progress)  # type: ignore[assignment]
    try:
        for item in items:
            yield item
            progress.update()
    finally:
        sys.stdout = saved
        progress.close()


class _ClearingStream:
    """Standard output that erases a drawn progress bar before it writes."""

    def __init__(self, stream: TextIO, progress: Progress) -> None:
        self._stream = stream
        self._progress = progress

    def write(self, text: str) -> int:
        """Erase the bar, then write."""
        if text:
            self._progress.clear()
        return self._stream.write(text)

    def __getattr__(self, name: str) -> object:
        """Everything else is the wrapped stream's."""
        return getattr(self._stream, name)
