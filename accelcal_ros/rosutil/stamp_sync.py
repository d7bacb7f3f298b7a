"""
Match messages of several streams by header stamp: the part of message_filters we need.

message_filters is not available as a wheel; this is its small equivalent, pure Python
(no rclpy), kept in this one module and tested in ``test/rosutil/test_stamp_sync.py``.

:class:`StampMatcher` keeps the last ``depth`` items of each stream (key) with their stamps
in seconds. :meth:`StampMatcher.nearest` returns, for a reference time, the item of each
stream nearest in time within a tolerance, or ``None`` for a stream that has nothing close
enough (a stalled camera, a missing attitude) -- callers decide whether a partial set is
usable, which ApproximateTime cannot express. Stamps may arrive out of order.
"""
import bisect
import threading


class StampMatcher:
    """Per-stream ring buffers of ``(stamp_s, item)``, queried by nearest stamp."""

    def __init__(self, keys, depth=10):
        if depth < 1:
            raise ValueError('depth must be at least 1')
        self._depth = int(depth)
        self._stamps = {k: [] for k in keys}
        self._items = {k: [] for k in keys}
        self._lock = threading.Lock()

    @property
    def keys(self):
        """Return the stream keys, in the order given."""
        return list(self._stamps)

    def add(self, key, stamp_s, item):
        """Store ``item`` of stream ``key`` at ``stamp_s`` (seconds), keeping stamps sorted."""
        with self._lock:
            stamps, items = self._stamps[key], self._items[key]
            index = bisect.bisect_right(stamps, stamp_s)
            stamps.insert(index, stamp_s)
            items.insert(index, item)
            if len(stamps) > self._depth:
                del stamps[0]
                del items[0]

    def latest_stamp(self, key=None):
        """Return the newest stamp of ``key`` (or of every stream); ``None`` if empty."""
        with self._lock:
            keys = [key] if key is not None else list(self._stamps)
            newest = [self._stamps[k][-1] for k in keys if self._stamps[k]]
        return max(newest) if newest else None

    def nearest(self, stamp_s, tolerance_s, keys=None):
        """
        Return ``{key: (stamp, item) or None}`` nearest to ``stamp_s`` within tolerance.

        A stream whose nearest stamp is further than ``tolerance_s`` away (or that is
        empty) maps to ``None``.
        """
        result = {}
        with self._lock:
            for key in keys if keys is not None else self._stamps:
                stamps = self._stamps[key]
                best = None
                index = bisect.bisect_left(stamps, stamp_s)
                for j in (index - 1, index):
                    if 0 <= j < len(stamps):
                        gap = abs(stamps[j] - stamp_s)
                        if gap <= tolerance_s and (best is None or gap < best[0]):
                            best = (gap, j)
                result[key] = None if best is None else (stamps[best[1]],
                                                         self._items[key][best[1]])
        return result

    def interpolated(self, key, stamp_s, tolerance_s):
        """
        Return ``(stamp_s, item)`` of stream ``key`` linearly interpolated at ``stamp_s``.

        Items are tuples of numbers. Between two stored stamps (each within
        ``tolerance_s``) the items are interpolated; otherwise the nearest within the
        tolerance is returned as it is, or ``None``.
        """
        with self._lock:
            stamps, items = self._stamps[key], self._items[key]
            index = bisect.bisect_left(stamps, stamp_s)
            if 0 < index < len(stamps):
                t0, t1 = stamps[index - 1], stamps[index]
                if stamp_s - t0 <= tolerance_s and t1 - stamp_s <= tolerance_s and t1 > t0:
                    w = (stamp_s - t0) / (t1 - t0)
                    a, b = items[index - 1], items[index]
                    return stamp_s, tuple(x + w * (y - x) for x, y in zip(a, b))
        return self.nearest(stamp_s, tolerance_s, keys=[key])[key]

    def clear(self, key=None):
        """Forget the items of ``key`` (or of every stream)."""
        with self._lock:
            for k in [key] if key is not None else list(self._stamps):
                self._stamps[k].clear()
                self._items[k].clear()
