"""
Dropped messages: counted in ``/diagnostics`` and logged (throttled), for every node.

A node that ignores a malformed message (a PointCloud2 without x/y/z, an image of an
unsupported encoding, an IMU sample with NaN) calls :meth:`DropCounter.drop` with a kind
and the reason. Each kind's count is published on ``/diagnostics``
(diagnostic_msgs/DiagnosticArray, one status named ``<node>: dropped messages``, WARN
while anything was dropped, the count and the last reason of every kind as values) every
``period_s`` and whenever a kind is dropped for the first time; the reason is logged as a
warning at most once per ``THROTTLE_S`` per kind, with the count so far.

It is the one home of a node's drop accounting: a pure core that counts its own drops
(a decode pool's replaced jobs, a filter's rejected samples) hands them on through a
callback or as a difference of its counter (``drop(kind, reason, n)``), and a node's
older diagnostics keys (``skipped_nan``, ``rejected_frames``, ...) are read from
:meth:`DropCounter.count`. The kinds of every node are listed in its documentation
(docs/*.md, "Dropped messages"). ``imu_driver``, ``calibration_frames`` and the scanner
simulation subscribe to nothing and have no message to drop (the driver's samples lost
in the sensor's FIFO are its ``fifo_overruns``).
"""
import math
import threading
import time
from typing import Dict, Tuple

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

THROTTLE_S = 10.0
"""Shortest time between two log lines about drops of one kind (s)."""
MAX_DETAILS = 8
"""Distinct ``detail`` values per kind throttled apart; further ones share one throttle."""


class DropCounter:
    """Count, log (throttled) and publish the messages a node drops, by kind."""

    def __init__(self, node, period_s: float = 1.0, what: str = 'dropped messages') -> None:
        self._node = node
        self._what = what
        self._lock = threading.Lock()
        self.counts: Dict[str, int] = {}
        self.reasons: Dict[str, str] = {}
        self._logged: Dict[Tuple[str, str], float] = {}
        self._publisher = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._timer = node.create_timer(period_s, self.publish)

    def drop(self, kind: str, reason: str, n: int = 1, detail: str = '') -> int:
        """
        Count ``n`` dropped messages of ``kind``; log ``reason`` (throttled); return count.

        ``detail``: a cause within the kind that is logged on its own throttle (e.g. a
        truncated JPEG and a PNG of the wrong size, both ``cam1_frames``); at most
        :data:`MAX_DETAILS` per kind, further ones share the kind's throttle.
        """
        if n <= 0:
            return self.count(kind)
        now = time.monotonic()
        with self._lock:
            previous = self.counts.get(kind, 0)
            count = previous + int(n)
            self.counts[kind] = count
            self.reasons[kind] = reason
            key = (kind, detail)
            if key not in self._logged and detail and sum(
                    1 for k in self._logged if k[0] == kind) >= MAX_DETAILS:
                key = (kind, '')
            log = now - self._logged.get(key, -math.inf) >= THROTTLE_S
            if log:  # per kind (rclpy's throttle is per call site: one for all kinds)
                self._logged[key] = now
        if log:
            self._node.get_logger().warning(
                f'{reason} ({kind} dropped so far: {count}; logged at most every '
                f'{THROTTLE_S:g} s, counted in /diagnostics)')
        if not previous:
            self.publish()
        return count

    def count(self, kind: str) -> int:
        """Return how many messages of ``kind`` were dropped so far."""
        with self._lock:
            return self.counts.get(kind, 0)

    def total(self, prefix: str = '') -> int:
        """Return the number of dropped messages of every kind starting with ``prefix``."""
        with self._lock:
            return sum(n for k, n in self.counts.items() if k.startswith(prefix))

    def publish(self) -> None:
        """Publish the counts on ``/diagnostics`` (OK with nothing dropped, else WARN)."""
        with self._lock:
            counts, reasons = dict(self.counts), dict(self.reasons)
        status = DiagnosticStatus(name=f'{self._node.get_name()}: {self._what}',
                                  hardware_id=self._node.get_name())
        if counts:
            status.level = DiagnosticStatus.WARN
            status.message = ', '.join(f'{n} {k}' for k, n in sorted(counts.items())) + \
                ' dropped'
        else:
            status.level, status.message = DiagnosticStatus.OK, 'nothing dropped'
        status.values = ([KeyValue(key=f'{k}_dropped', value=str(n))
                          for k, n in sorted(counts.items())]
                         + [KeyValue(key=f'{k}_last_reason', value=reasons[k])
                            for k in sorted(reasons)])
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self._node.get_clock().now().to_msg()
        try:
            self._publisher.publish(msg)
        except Exception:  # noqa: B902 - the context is shutting down: nothing to report
            pass
