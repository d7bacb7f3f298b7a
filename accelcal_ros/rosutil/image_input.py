"""
image_transport's ``compressed`` input for image nodes: subscriptions plus a decode pool.

``image_transport:=compressed`` on the stitcher or ``p2p`` subscribes
``<resolved base topic>/compressed`` (sensor_msgs/CompressedImage; the base topic's
remapping applies, as in image_transport) instead of the raw topic.
:class:`CompressedInputs` receives the serialized messages (``raw=True``: no
deserialisation), reads the header in the executor's callback and decodes the JPEG/PNG in
a :class:`~.decode_pool.DecodePool` thread (one per topic: the cameras decode in
parallel; per camera in order, the newest frame only when decoding falls behind).

The node's ``on_frame(index, raw, array, encoding)`` and ``on_reject(index, reason)``
run in the pool's threads: a frame that does not decode
(:func:`~.compressed.decode_compressed` says why in one line) is counted in
:attr:`CompressedInputs.rejected` and handed to ``on_reject``; nothing waits for it. A
frame replaced by a newer one before it was decoded goes to ``on_replaced(index)`` (the
executor's thread), for the node's DropCounter.
"""
from collections import deque
import threading
import time

from accelcal_ros.errors import InputError
from accelcal_ros.rosutil.compressed import decode_compressed, parse_compressed_cdr
from accelcal_ros.rosutil.decode_pool import DecodePool

TRANSPORTS = ('raw', 'compressed')
"""Values of the nodes' ``image_transport`` parameter."""


def compressed_topic(node, base):
    """image_transport's topic of the ``compressed`` plugin for ``base``: resolved + suffix."""
    return node.resolve_topic_name(base).rstrip('/') + '/compressed'


class CompressedInputs:
    """CompressedImage subscriptions of ``topics`` decoded off the executor (see module)."""

    def __init__(self, node, topics, qos, on_frame, on_reject, expected_sizes=None,
                 callback_group=None, events=None, on_replaced=None):
        from sensor_msgs.msg import CompressedImage

        self.topics = list(topics)
        count = len(self.topics)
        self._on_frame = on_frame
        self._on_reject = on_reject
        self._sizes = list(expected_sizes) if expected_sizes else [None] * count
        self._logger = node.get_logger()
        self._lock = threading.Lock()
        self._decode_s = deque(maxlen=100)
        self.received = [0] * count
        """Messages received per topic."""
        self.rejected = [0] * count
        """Messages per topic that did not decode (or were no CompressedImage)."""
        self.pool = DecodePool(count, 'decode', on_error=self._job_failed,
                               on_replace=on_replaced)
        for i, topic in enumerate(self.topics):
            node.create_subscription(
                CompressedImage, topic, lambda data, i=i: self._receive(i, data), qos,
                callback_group=callback_group, raw=True,
                event_callbacks=events(i) if events is not None else None)

    def _receive(self, index, data):
        """Executor thread: read the header only, queue the decode."""
        self.received[index] += 1
        try:
            raw = parse_compressed_cdr(data)
        except InputError as exc:
            self._reject(index, f'{self.topics[index]}: {exc}')
            return
        self.pool.submit(index, self._decode, index, raw)

    def _reject(self, index, reason):
        with self._lock:
            self.rejected[index] += 1
        self._on_reject(index, reason)

    def _decode(self, index, raw):
        """Pool thread: decode, then hand the array to the node."""
        start = time.perf_counter()
        try:
            array, encoding = decode_compressed(raw.payload(), raw.format,
                                                topic=self.topics[index],
                                                expected_size=self._sizes[index])
        except InputError as exc:
            self._reject(index, str(exc))
            return
        with self._lock:
            self._decode_s.append(time.perf_counter() - start)
        self._on_frame(index, raw, array, encoding)

    def _job_failed(self, index, exc):
        self._logger.error(f'{self.topics[index]}: handling a decoded frame failed: '
                           f'{type(exc).__name__}: {exc}', throttle_duration_sec=10.0)

    def decode_ms(self):
        """Mean decode time of the recent frames (ms); NaN before the first."""
        with self._lock:
            times = list(self._decode_s)
        return 1e3 * sum(times) / len(times) if times else float('nan')

    def close(self):
        """Stop the decode threads (waits for the running decodes)."""
        self.pool.close()
