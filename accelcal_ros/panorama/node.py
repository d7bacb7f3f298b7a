"""
``stitcher``: levelled video panorama from a camera rig and the attitude (thin ROS wiring).

Subscribes (``image_reliability``: best_effort -- sensor-data QoS, which matches every
publisher -- or reliable, lossless for large images from reliable publishers):

* each of ``camera_topics`` (sensor_msgs/Image; rgb8, bgr8 or mono8; other encodings and
  images whose size differs from the rig file are rejected with a log line, once);
* ``attitude`` (geometry_msgs/Vector3Stamped: x = roll, y = pitch, rad, REP-103), as
  published by the ``attitude`` node; NaN or infinite values are rejected.

Publishes ``panorama`` (sensor_msgs/Image, reliable, depth 2) stamped with the newest
camera frame used, and ``/diagnostics`` (one status per camera, one for the panorama).

Frames of the cameras are matched by stamp within ``sync_tolerance_s``
(:class:`~accelcal_ros.rosutil.stamp_sync.StampMatcher`); a camera silent for more than
``stale_timeout_s`` is stalled: the others go on and its sector stays black. Before the
first attitude arrives nothing is published (said once). Matching, image copies and
lookup rebuilds run in a worker thread, so subscriptions never wait for them; with
``pipeline`` (default) each frame is remapped and published from a render thread while
the next frame set's lookup is rebuilt. Core: :class:`~.pipeline.PipelinedStitcher`.
"""
import math
import threading
import time

from accelcal_ros.errors import AccelcalError, InputError
from accelcal_ros.frames import rotation_matrix_from_list
from accelcal_ros.panorama.params import STITCHER_PARAMS
from accelcal_ros.panorama.pipeline import PipelinedStitcher
from accelcal_ros.panorama.projection import PanoramaGeometry
from accelcal_ros.panorama.rig import load_rig
from accelcal_ros.rosutil.images import array_to_image_msg, image_msg_to_array
from accelcal_ros.rosutil.params import ParameterSet
from accelcal_ros.rosutil.runner import run
from accelcal_ros.rosutil.stamp_sync import StampMatcher
from accelcal_ros.rosutil.stamps import seconds_to_stamp, stamp_to_seconds
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Vector3Stamped
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image


class StitcherNode(Node):
    """Thin node around :class:`~accelcal_ros.panorama.pipeline.PipelinedStitcher`."""

    def __init__(self):
        super().__init__('stitcher')
        import cv2

        self.params = ParameterSet(self, STITCHER_PARAMS)
        v = self.params.values
        if v['threads']:
            cv2.setNumThreads(int(v['threads']))
        if not v['rig_file']:
            raise InputError('parameter rig_file is required (the rig YAML: cameras with '
                             'name, width, height, K, D, R)')
        self.rig = load_rig(v['rig_file'])
        topics = list(v['camera_topics']) or [f'{name}/image_raw' for name in self.rig.names]
        if len(topics) != len(self.rig):
            raise InputError(f'camera_topics has {len(topics)} topic(s) but the rig has '
                             f'{len(self.rig)} cameras ({", ".join(self.rig.names)})')
        self.topics = topics
        geometry = PanoramaGeometry(v['width'], v['height'], v['fov_h_deg'], v['fov_v_deg'],
                                    v['projection'])
        self.encoding = v['output_encoding']
        self.stitcher = PipelinedStitcher(
            self.rig, geometry, rotation_matrix_from_list(v['imu_to_camera'], 'imu_to_camera'),
            stages=2 if v['pipeline'] else 1, grid_step=v['grid_step'],
            rebuild_threshold_deg=v['rebuild_threshold_deg'],
            blend_width_deg=v['blend_width_deg'],
            channels=1 if self.encoding == 'mono8' else 3)
        n = len(self.rig)
        self.frames = StampMatcher(list(range(n)), depth=4)
        self.attitudes = StampMatcher(['attitude'], depth=500)
        self._last_receive = [None] * n
        self._rejected = [0] * n
        self._received = [0] * n
        self._reject_reason = [''] * n
        self._stall_warned = [False] * n
        self._warned = set()
        self._wake = threading.Event()
        self._stop = False
        self._lock = threading.Lock()
        self._last_published = -math.inf
        self._last_tried = -math.inf
        self._unmatched_since = None
        self._waiting = None
        self._retry = False
        self._published = 0
        self._publish_times = []
        self._latency_s = float('nan')
        self._process_s = float('nan')
        self._status = 'waiting for camera frames'
        group = ReentrantCallbackGroup()
        qos = qos_profile_sensor_data if v['image_reliability'] == 'best_effort' else \
            QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE)
        for i, topic in enumerate(topics):
            self.create_subscription(Image, topic, lambda msg, i=i: self._on_image(i, msg),
                                     qos, callback_group=group)
        self.create_subscription(Vector3Stamped, 'attitude', self._on_attitude,
                                 qos_profile_sensor_data, callback_group=group)
        self.publisher = self.create_publisher(Image, 'panorama', 2)
        self.diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_timer(1.0, self._publish_diagnostics)
        self._worker = threading.Thread(target=self._work, name='stitcher', daemon=True)
        self._worker.start()
        inputs = ', '.join(f'{c.name} <- {t}' for c, t in zip(self.rig.cameras, topics))
        self.get_logger().info(
            f'stitching {n} cameras ({inputs}) into a {geometry.width}x{geometry.height} '
            f'{geometry.projection} panorama of {geometry.fov_h_deg:g} x '
            f'{geometry.fov_v_deg:g} deg on "panorama"')

    # -- helpers --------------------------------------------------------------------------
    def _warn_once(self, key, text):
        if key not in self._warned:
            self._warned.add(key)
            self.get_logger().warning(text)

    def close(self):
        """Stop the worker thread (called by the runner at shutdown)."""
        self._stop = True
        self._wake.set()
        self._worker.join(timeout=2.0)
        self.stitcher.close()

    # -- inputs ---------------------------------------------------------------------------
    def _on_image(self, index, msg):
        cam = self.rig.cameras[index]
        try:
            image = image_msg_to_array(msg, want=self.encoding)
            if (msg.width, msg.height) != (cam.width, cam.height):
                raise InputError(f'image is {msg.width}x{msg.height}, the rig file says '
                                 f'{cam.width}x{cam.height}')
        except InputError as exc:
            self._rejected[index] += 1
            self._reject_reason[index] = str(exc)
            self._warn_once(('image', index, str(exc)),
                            f'camera {cam.name} ({self.topics[index]}): frame rejected: {exc} '
                            '(reported once)')
            return
        self.frames.add(index, stamp_to_seconds(msg.header.stamp), image)
        self._received[index] += 1
        self._last_receive[index] = time.monotonic()
        self._wake.set()

    def _on_attitude(self, msg):
        roll, pitch = msg.vector.x, msg.vector.y
        if not (math.isfinite(roll) and math.isfinite(pitch)):
            self._warn_once('nan_attitude', f'attitude rejected: roll={roll}, pitch={pitch} '
                            'is not finite; the last good attitude stays in use (reported '
                            'once)')
            return
        self.attitudes.add('attitude', stamp_to_seconds(msg.header.stamp), (roll, pitch))
        self._wake.set()

    # -- stitching ------------------------------------------------------------------------
    def _work(self):
        while not self._stop:
            self._wake.wait(timeout=0.005 if self._retry else 0.1)
            self._wake.clear()
            self._retry = False
            if self._stop:
                break
            try:
                self._try_stitch()
            except AccelcalError as exc:
                self._warn_once(('error', str(exc)), f'cannot stitch: {exc}')
            except Exception as exc:  # keep the node alive; say what happened
                self._warn_once(('crash', type(exc).__name__),
                                f'stitching failed: {type(exc).__name__}: {exc}')

    def _live_cameras(self, now):
        timeout = self.params['stale_timeout_s']
        live = []
        for i, last in enumerate(self._last_receive):
            cam = self.rig.cameras[i]
            if last is not None and now - last <= timeout:
                live.append(i)
                if self._stall_warned[i]:
                    self._stall_warned[i] = False
                    self.get_logger().info(f'camera {cam.name} ({self.topics[i]}) is back')
            elif last is not None and not self._stall_warned[i]:
                self._stall_warned[i] = True
                self.get_logger().warning(
                    f'camera {cam.name} ({self.topics[i]}) stalled: no frame for '
                    f'{now - last:.1f} s; its sector stays black, the others go on')
        return live

    def _report_unmatched(self, candidates, live, tolerance, now):
        """Say once when the live cameras' stamps never come within the tolerance."""
        if not candidates or candidates[0] <= self._last_published:
            return
        if self._unmatched_since is None:
            self._unmatched_since = now
            return
        if now - self._unmatched_since < 2.0:
            return
        newest = candidates[0]
        offsets = []
        for i in live:
            near = self.frames.nearest(newest, math.inf, keys=[i])[i]
            if near is not None and abs(near[0] - newest) > tolerance:
                offsets.append(f'{self.rig.cameras[i].name} {1e3 * (near[0] - newest):+.0f} ms')
        self._status = 'no complete set of frames within sync_tolerance_s'
        self._warn_once('unmatched', 'no set of frames with stamps within sync_tolerance_s = '
                        f'{tolerance} s for 2 s (offsets from the newest frame: '
                        f'{", ".join(offsets) or "none"}); trigger the cameras together or '
                        'raise sync_tolerance_s (reported once)')

    def _try_stitch(self):
        now = time.monotonic()
        live = self._live_cameras(now)
        if not live:
            return
        tolerance = self.params['sync_tolerance_s']
        candidates = sorted({self.frames.latest_stamp(i) for i in live} - {None},
                            reverse=True)
        chosen = None
        for stamp in candidates:
            if stamp <= self._last_published or stamp <= self._last_tried:
                break
            match = self.frames.nearest(stamp, tolerance, keys=live)
            if all(match[i] is not None for i in live):
                chosen = (stamp, match)
                break
        if chosen is None:
            self._report_unmatched(candidates, live, tolerance, now)
            return
        self._unmatched_since = None
        stamp, match = chosen
        newest = max(m[0] for m in match.values())
        if self.attitudes.latest_stamp() is None:
            self._status = 'no attitude yet'
            self._warn_once('no_attitude', 'no attitude received yet on "attitude" '
                            '(geometry_msgs/Vector3Stamped, x roll, y pitch, rad): '
                            'publishing nothing until one arrives')
            self._last_tried = newest
            return
        # The attitude of the frames' instant may still be on its way (topics are not
        # ordered): wait up to attitude_wait_s for one stamped at or after the frames.
        if self.attitudes.latest_stamp() < newest - 1e-6:
            if self._waiting is None or self._waiting[0] != newest:
                self._waiting = (newest, now)
            if now - self._waiting[1] < self.params['attitude_wait_s']:
                self._retry = True
                return
        self._waiting = None
        attitude = self.attitudes.nearest(newest, self.params['attitude_tolerance_s'])
        if attitude['attitude'] is None:
            self._status = 'no attitude near the frame stamps'
            self._warn_once('attitude_gap', f'no attitude within '
                            f'{self.params["attitude_tolerance_s"]} s of the frame stamp '
                            f'{newest:.3f}: frames skipped (check clocks / the attitude '
                            'node; reported once)')
            self._last_tried = newest
            return
        start = time.perf_counter()
        roll, pitch = attitude['attitude'][1]
        self.stitcher.rebuild_threshold_deg = self.params['rebuild_threshold_deg']
        images = [match[i][1] if match.get(i) is not None else None
                  for i in range(len(self.rig))]
        # the remap and the publishing run in the render thread (the next frame set's
        # lookup is rebuilt meanwhile); bad input raises here, before anything is queued
        self.stitcher.submit(roll, pitch, images,
                             lambda panorama: self._publish(panorama, newest, start))
        self._last_published = newest

    def _publish(self, panorama, stamp, start):
        """Publish one panorama (render thread); errors are logged, not raised."""
        try:
            header = Image().header
            header.stamp = seconds_to_stamp(stamp, Time)
            header.frame_id = self.params['frame_id']
            msg = array_to_image_msg(panorama, self.encoding, Image, header)
            self.publisher.publish(msg)
        except Exception as exc:  # keep rendering; say what happened
            self._warn_once(('publish', type(exc).__name__),
                            f'publishing the panorama failed: {type(exc).__name__}: {exc}')
            return
        now = time.monotonic()
        self._published += 1
        self._process_s = time.perf_counter() - start
        self._latency_s = self.get_clock().now().nanoseconds * 1e-9 - stamp
        self._publish_times = [t for t in self._publish_times if t > now - 5.0] + [now]
        self._status = 'publishing'

    # -- diagnostics ----------------------------------------------------------------------
    def _publish_diagnostics(self):
        now = time.monotonic()
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        times = [t for t in self._publish_times if t > now - 5.0]
        fps = (len(times) - 1) / (times[-1] - times[0]) if len(times) > 1 \
            and times[-1] > times[0] else 0.0
        main = DiagnosticStatus(name='stitcher: panorama', hardware_id='stitcher')
        main.level = DiagnosticStatus.OK if self._status == 'publishing' else \
            DiagnosticStatus.WARN
        main.message = self._status
        main.values = [
            KeyValue(key='published', value=str(self._published)),
            KeyValue(key='rate_hz', value=f'{fps:.2f}'),
            KeyValue(key='latency_ms', value=f'{1e3 * self._latency_s:.1f}'),
            KeyValue(key='processing_ms', value=f'{1e3 * self._process_s:.1f}'),
            KeyValue(key='lookup_rebuilds', value=str(self.stitcher.rebuild_count)),
            KeyValue(key='last_rebuild_ms', value=f'{1e3 * self.stitcher.last_rebuild_s:.1f}'),
        ]
        statuses = [main]
        timeout = self.params['stale_timeout_s']
        for i, cam in enumerate(self.rig.cameras):
            last = self._last_receive[i]
            status = DiagnosticStatus(name=f'stitcher: camera {cam.name}',
                                      hardware_id=self.topics[i])
            age = None if last is None else now - last
            if age is None:
                status.level = DiagnosticStatus.WARN if not self._rejected[i] else \
                    DiagnosticStatus.ERROR
                status.message = 'no frame received yet; sector black' if not \
                    self._rejected[i] else f'all frames rejected: {self._reject_reason[i]}'
            elif age > timeout:
                status.level = DiagnosticStatus.WARN
                status.message = f'stalled: no frame for {age:.1f} s; sector black'
            else:
                status.level = DiagnosticStatus.OK
                status.message = 'ok'
            status.values = [
                KeyValue(key='topic', value=self.topics[i]),
                KeyValue(key='frame_age_s', value='inf' if age is None else f'{age:.2f}'),
                KeyValue(key='received_frames', value=str(self._received[i])),
                KeyValue(key='rejected_frames', value=str(self._rejected[i])),
            ]
            statuses.append(status)
        array.status = statuses
        self.diagnostics.publish(array)


def main(args=None):
    """Run the ``stitcher`` node."""
    return run(StitcherNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
