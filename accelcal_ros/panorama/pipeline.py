"""
Stitchers in turn: frame k+1's lookup is rebuilt while frame k is remapped.

A lookup rebuild is numpy work on one core; the remap keeps every OpenCV thread busy. One
after the other, a core idles during each rebuild -- with the attitude changing every
frame, a third of the time on a 2-core machine. :class:`PipelinedStitcher` keeps
``stages`` :class:`~.stitch.Stitcher` objects (each with its own mosaic, lookup and output
buffer) and hands every frame's remap to one worker thread, so that the next frame's
image copies and rebuild run meanwhile. One frame's latency stays what it was; the
throughput rises (``benchmarks/bench_panorama.py`` prints both). Frames are rendered and
delivered in the order they were submitted. ``stages=1`` is the plain sequence (half the
memory: at 3600x2400 each stage holds about 80-100 MB).
"""
from concurrent.futures import Future, ThreadPoolExecutor, wait
from typing import Any, Callable, List, Optional, Sequence

from accelcal_ros.errors import InputError
from accelcal_ros.panorama.stitch import Stitcher


class PipelinedStitcher:
    """
    Submit frame sets; each panorama is handed to a callback from the render thread.

    Typical use::

        stitchers = PipelinedStitcher(rig, PanoramaGeometry(3600, 2400, 180, 120))
        future = stitchers.submit(roll, pitch, images, publish)  # publish(panorama)
        ...
        stitchers.close()                                         # waits for the last

    ``options`` are :class:`~.stitch.Stitcher`'s keyword arguments.
    """

    def __init__(self, rig: Any, geometry: Any, *args: Any, stages: int = 2,
                 **options: Any) -> None:
        if stages not in (1, 2):
            raise InputError(f'stages must be 1 or 2, got {stages!r}')
        self.stitchers = [Stitcher(rig, geometry, *args, **options) for _ in range(stages)]
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix='panorama_remap')
        self._pending: List[Optional[Future]] = [None] * stages
        self._submitted = 0
        self.last_rebuild_s = float('nan')
        """Duration of the latest rebuild (seconds; NaN before the first)."""

    @property
    def rebuild_threshold_deg(self) -> float:
        """Tilt change (degrees) that triggers a lookup rebuild (every stage alike)."""
        return self.stitchers[0].rebuild_threshold_deg

    @rebuild_threshold_deg.setter
    def rebuild_threshold_deg(self, value: float) -> None:
        for stitcher in self.stitchers:
            stitcher.rebuild_threshold_deg = float(value)

    @property
    def rebuild_count(self) -> int:
        """Lookup rebuilds so far, all stages together."""
        return sum(s.rebuild_count for s in self.stitchers)

    def submit(self, roll: float, pitch: float, images: Sequence[Any],
               consume: Callable[[Any], Any]) -> Future:
        """
        Stitch one frame set (radians; images in rig order, None: camera blacked out).

        ``consume(panorama)`` is called from the render thread with the stage's output
        buffer, valid during the call only (copy or serialise it there). Returns a
        ``concurrent.futures.Future`` of consume's result. Bad input raises
        :class:`InputError` here, before anything is queued or changed. Waits while the
        stage's previous frame is still being rendered.
        """
        index = self._submitted % len(self.stitchers)
        stitcher = self.stitchers[index]
        pending = self._pending[index]
        if pending is not None:
            wait([pending])
        if stitcher.update(roll, pitch, images):
            self.last_rebuild_s = stitcher.last_rebuild_s
        future = self._worker.submit(self._render, stitcher, consume)
        self._pending[index] = future
        self._submitted += 1
        return future

    @staticmethod
    def _render(stitcher: Stitcher, consume: Callable[[Any], Any]) -> Any:
        return consume(stitcher.render())

    def drain(self) -> None:
        """Wait until every submitted frame has been rendered and consumed."""
        wait([f for f in self._pending if f is not None])

    def close(self) -> None:
        """Finish the submitted frames and stop the render thread."""
        self._worker.shutdown(wait=True)
