"""
``stitcher``: levelled video panorama from a camera rig and the attitude (thin ROS wiring).

Subscribes:

* each of ``camera_topics`` (sensor_msgs/Image in any encoding of
  :mod:`accelcal_ros.rosutil.images`: bgr8, rgb8, mono8/16, rgba8/bgra8, Bayer, YUV 4:2:2;
  images whose size differs from the rig file are rejected, counted, logged: see below). QoS
  ``image_reliability``: ``reliable`` (default) keep-last ``image_queue_depth``: every
  frame of a reliable camera driver arrives whole, and a slow node only drops older
  frames (keep-last: the publisher never waits for it); ``best_effort`` for best-effort
  publishers (a reliable subscription receives nothing from them: said in the log).
  The subscriptions are raw: the pixels are numpy views on the received buffer, copied
  once, into the mosaic. ``image_transport:=compressed`` subscribes ``<topic>/compressed``
  instead (sensor_msgs/CompressedImage, JPEG/PNG as image_transport writes them), decoded
  in parallel off the executor (:mod:`accelcal_ros.rosutil.image_input`); a frame that
  does not decode is counted as rejected and skipped.
* ``attitude`` (geometry_msgs/Vector3Stamped: x = roll, y = pitch, rad, REP-103), as
  published by the ``attitude`` node; NaN, infinite and out-of-range values (roll beyond
  +-pi, pitch beyond +-pi/2) are rejected and counted (``rejected_attitudes``).

Publishes ``panorama`` (sensor_msgs/Image, reliable, depth 2; serialized directly from
the render buffer, skipped while nobody subscribes) stamped with the newest camera frame
used, ``panorama/compressed`` (sensor_msgs/CompressedImage, JPEG, only with
``compressed_output``) and ``/diagnostics`` (one status per camera, one for the
panorama, with the time jumps seen).

Which frames form a set (stamps within ``sync_tolerance_s``, stalled cameras, waiting
for the attitude, time jumps) is :class:`~.frame_sets.FrameSetPolicy`; its one thread
(:class:`~.frame_sets.FrameSetWorker`) hands each set to
:class:`~.pipeline.PipelinedStitcher`, whose render thread remaps and publishes while
the next set's lookup is rebuilt. A stamp that jumps by more than
``time_jump_threshold_s`` against the wall time (a bag replayed in a loop, a clock set)
resets the policy, with a log line and the count in ``/diagnostics``.
Every dropped input -- a frame of the wrong size or encoding or that does not decode
(``<camera>_frames``), a compressed frame replaced by a newer one before it was decoded
(``<camera>_frames_replaced``), a refused attitude (``attitudes``), a set skipped for
want of an attitude near its stamp (``frame_sets``), a refused ``roi/<name>/steer``
(``roi_steer``) and a frame set the levelled views' thread had no time for
(``roi_frame_sets``) -- is counted in one :class:`~accelcal_ros.rosutil.drops.DropCounter`
(``stitcher: dropped messages``) and logged at most every 10 s per kind.
``imu_to_camera`` comes from the rig file when it has one; the parameter, when given,
overrides it.
"""
import math
import os
import time

from accelcal_ros.camera.rig import load_rig, resolve_imu_to_camera
from accelcal_ros.errors import AccelcalError, InputError
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA
from accelcal_ros.jpeg import encode_jpeg
from accelcal_ros.panorama.frame_sets import FrameSetPolicy, FrameSetWorker
from accelcal_ros.panorama.params import panorama_size, STITCHER_PARAMS
from accelcal_ros.panorama.pipeline import PipelinedStitcher
from accelcal_ros.panorama.projection import PanoramaGeometry
from accelcal_ros.panorama.roi_node import RoiViews
from accelcal_ros.rosutil.dds import large_message_profile_path, use_large_message_profile
from accelcal_ros.rosutil.drops import DropCounter
from accelcal_ros.rosutil.image_input import compressed_topic, CompressedInputs
from accelcal_ros.rosutil.images import (convert_color, image_array, image_cdr,
                                         parse_image_cdr)
from accelcal_ros.rosutil.params import ParameterSet
from accelcal_ros.rosutil.runner import run
from accelcal_ros.rosutil.stamps import stamp_to_seconds
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Vector3Stamped
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import (HistoryPolicy, qos_profile_sensor_data, QoSProfile,
                       ReliabilityPolicy)
from sensor_msgs.msg import CompressedImage, Image

# Inputs that go into the mosaic as they are (the stitcher converts grey <-> BGR while
# copying); any other encoding is converted to the output encoding first.
FASTDDS_DEFAULT_SHM_MB = 0.5
"""Fast DDS's default shared-memory segment (MB): larger messages go over UDP."""
_AS_IS = {'bgr8': ('bgr8', 'mono8'), 'mono8': ('mono8', 'bgr8'), 'rgb8': ('rgb8', 'mono8')}


class StitcherNode(Node):
    """Thin node around :class:`~.frame_sets.FrameSetPolicy` and the stitcher."""

    def __init__(self):
        super().__init__('stitcher')
        import cv2

        self.params = ParameterSet(self, STITCHER_PARAMS)
        self.drops = DropCounter(self)
        self.roi = RoiViews(self, self.drops)  # levelled views roi/<name>: their parameters
        v = self.params.values
        if v['threads']:
            cv2.setNumThreads(int(v['threads']))
        if not v['rig_file']:
            raise InputError('parameter rig_file is required (the rig YAML: cameras with '
                             'name, width, height, K, D, R)')
        self.rig = load_rig(v['rig_file'])
        if v['camera_info_topics']:   # K and D from the drivers, checked against the sizes
            from accelcal_ros.rosutil.camera_info import rig_from_camera_info
            self.rig = rig_from_camera_info(self, self.rig, v['camera_info_topics'],
                                            v['camera_info_timeout_s'])
        topics = list(v['camera_topics']) or [f'{name}/image_raw' for name in self.rig.names]
        if len(topics) != len(self.rig):
            raise InputError(f'camera_topics has {len(topics)} topic(s) but the rig has '
                             f'{len(self.rig)} cameras ({", ".join(self.rig.names)})')
        if v['image_transport'] == 'compressed':
            topics = [compressed_topic(self, t) for t in topics]
        self.topics = topics
        width, height, focal_px = panorama_size(self.rig, v['width'], v['height'],
                                                v['fov_h_deg'], v['fov_v_deg'],
                                                v['projection'])
        geometry = PanoramaGeometry(width, height, v['fov_h_deg'], v['fov_v_deg'],
                                    v['projection'])
        size_from = 'width/height parameters' if focal_px is None else (
            f'the rig: camera 0 f = {focal_px:.1f} px = {focal_px * math.pi / 180.0:.2f} '
            'px/deg over the sector, rounded to even')
        self.encoding = v['output_encoding']
        mount, source = self._imu_to_camera(v)
        self.stitcher = PipelinedStitcher(
            self.rig, geometry, mount, stages=2 if v['pipeline'] else 1,
            grid_step=v['grid_step'], rebuild_threshold_deg=v['rebuild_threshold_deg'],
            blend_width_deg=v['blend_width_deg'],
            channels=1 if self.encoding == 'mono8' else 3)
        self.roi.start(self.rig, mount, self.encoding, lambda: self.params['frame_id'])
        self._sizes = [(c.width, c.height) for c in self.rig.cameras]
        self.policy = FrameSetPolicy(
            [f'{c.name} ({t})' for c, t in zip(self.rig.cameras, topics)], self.params,
            log=self._log, jump_threshold_s=v['time_jump_threshold_s'],
            on_drop=self.drops.drop, names=self.rig.names)
        self._published = 0
        self._publish_times = []
        self._latency_s = float('nan')
        self._process_s = float('nan')
        self._error = ''
        self._warned = set()
        group = ReentrantCallbackGroup()
        reliable = v['image_reliability'] == 'reliable'
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=v['image_queue_depth'],
                         reliability=ReliabilityPolicy.RELIABLE if reliable
                         else ReliabilityPolicy.BEST_EFFORT)
        self.inputs = None
        for i, topic in enumerate(topics if v['image_transport'] == 'raw' else ()):
            events = SubscriptionEventCallbacks(
                incompatible_qos=lambda event, i=i: self._incompatible(i, event))
            self.create_subscription(Image, topic, lambda data, i=i: self._on_image(i, data),
                                     qos, callback_group=group, raw=True,
                                     event_callbacks=events)
        if v['image_transport'] == 'compressed':
            self.inputs = CompressedInputs(
                self, topics, qos, self._on_decoded, self.policy.reject_frame,
                expected_sizes=self._sizes, callback_group=group,
                on_replaced=self._replaced,
                events=lambda i: SubscriptionEventCallbacks(
                    incompatible_qos=lambda event, i=i: self._incompatible(i, event)))
        self.create_subscription(Vector3Stamped, 'attitude', self._on_attitude,
                                 qos_profile_sensor_data, callback_group=group)
        self.publisher = self.create_publisher(Image, 'panorama', 2)
        self.compressed = self.create_publisher(CompressedImage, 'panorama/compressed', 2) \
            if v['compressed_output'] else None
        self.diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_timer(1.0, self._publish_diagnostics)
        self.worker = FrameSetWorker(self.policy, self._stitch, self._on_error,
                                     recoverable=(Exception,))  # the thread always lives
        inputs = ', '.join(f'{c.name} <- {t}' for c, t in zip(self.rig.cameras, topics))
        self.get_logger().info(
            f'stitching {len(self.rig)} cameras ({inputs}) into a {geometry.width}x'
            f'{geometry.height} {geometry.projection} panorama of {geometry.fov_h_deg:g} x '
            f'{geometry.fov_v_deg:g} deg on "panorama" (images {v["image_reliability"]}, '
            f'depth {v["image_queue_depth"]}, {v["image_transport"]}; size from '
            f'{size_from}; imu_to_camera from '
            f'{source})')
        self._transport_hint(geometry)

    def _transport_hint(self, geometry):
        """Say once when frames of this size need the camera drivers' DDS profile too."""
        from rclpy.utilities import get_rmw_implementation_identifier

        if get_rmw_implementation_identifier() != 'rmw_fastrtps_cpp':
            return
        frame_mb = max(c.width * c.height * 3 for c in self.rig.cameras) / 2 ** 20
        out_mb = geometry.width * geometry.height * 3 / 2 ** 20
        if max(frame_mb, out_mb) <= FASTDDS_DEFAULT_SHM_MB:
            return
        profile = os.environ.get('FASTRTPS_DEFAULT_PROFILES_FILE') or os.environ.get(
            'FASTDDS_DEFAULT_PROFILES_FILE')
        if profile == large_message_profile_path():
            self.get_logger().info(
                f'frames of {frame_mb:.1f} MB and panoramas of {out_mb:.1f} MB exceed Fast '
                f"DDS's default shared-memory segment ({FASTDDS_DEFAULT_SHM_MB} MB): this node "
                f'uses {profile}; start the camera drivers (and viewers) with '
                f'FASTRTPS_DEFAULT_PROFILES_FILE={profile} too, or their frames go over UDP '
                'loopback, where they are lost at camera rates')
        elif not profile:
            self.get_logger().info(
                f'messages of {frame_mb:.1f} MB (frames) and {out_mb:.1f} MB (panorama) '
                f'exceed the default shared-memory segment of Fast DDS ({FASTDDS_DEFAULT_SHM_MB} '
                'MB): they go over UDP loopback, where frames are lost at camera rates; give '
                'every process a profile with a larger segment (FASTRTPS_DEFAULT_PROFILES_FILE'
                ', see docs/panorama.md "In a graph")')

    def _imu_to_camera(self, values):
        """
        Return ``(rotation, where it came from)``: the parameter if given, else the rig's.

        A value equal to the default (as config/stitcher.yaml lists it) counts as not
        given: the rig file's mounting is not overridden by the listed default.
        """
        default = [float(x) for x in DEFAULT_IMU_TO_CAMERA.reshape(-1)]
        given = 'imu_to_camera' in (getattr(self, '_parameter_overrides', None) or {}) \
            and [float(x) for x in values['imu_to_camera']] != default
        return resolve_imu_to_camera(self.rig, values['imu_to_camera'] if given else None,
                                     name='parameter imu_to_camera')

    # -- helpers --------------------------------------------------------------------------
    def _log(self, level, text):
        # one call site per severity: rclpy refuses a second severity at one call site
        if level == 'warning':
            self.get_logger().warning(text)
        else:
            self.get_logger().info(text)

    def _warn_once(self, key, text):
        if key not in self._warned:
            self._warned.add(key)
            self.get_logger().warning(text)

    def _incompatible(self, index, event):
        self._warn_once(('qos', index), f'camera topic {self.topics[index]}: a publisher '
                        'with incompatible QoS (best effort?) is ignored; set '
                        'image_reliability:=best_effort for best-effort camera drivers')

    def close(self):
        """Stop the frame-set thread and the render thread (the runner calls this)."""
        if self.inputs is not None:
            self.inputs.close()
        self.worker.close()
        self.stitcher.close()
        self.roi.close()

    # -- inputs ---------------------------------------------------------------------------
    def _on_image(self, index, data):
        """Raw (serialized) image: parse the header, keep a view on the pixels."""
        topic = self.topics[index]
        try:
            raw = parse_image_cdr(data)
            enc = raw.encoding.lower()
            want = None if self.encoding in _AS_IS.get(enc, ()) else self.encoding
            image = image_array(raw.height, raw.width, raw.encoding, raw.is_bigendian,
                                raw.step, raw.data, raw.offset, want=want, topic=topic,
                                expected_size=self._sizes[index], length=raw.length)
        except InputError as exc:
            self.policy.reject_frame(index, str(exc))
            return
        self.policy.add_frame(index, raw.stamp_s, image, time.monotonic())
        self.worker.wake()

    def _replaced(self, index):
        self.drops.drop(f'{self.rig.names[index]}_frames_replaced',
                        f'{self.topics[index]}: a frame replaced by a newer one before it was '
                        'decoded (decoding falls behind; the newest frame is kept)')

    def _on_decoded(self, index, raw, image, encoding):
        """Queue a decoded compressed frame (decode thread), converted if needed."""
        want = None if self.encoding in _AS_IS.get(encoding, ()) else self.encoding
        self.policy.add_frame(index, raw.stamp_s, convert_color(image, encoding, want),
                              time.monotonic())
        self.worker.wake()

    def _on_attitude(self, msg):
        if self.policy.add_attitude(stamp_to_seconds(msg.header.stamp), msg.vector.x,
                                    msg.vector.y, time.monotonic()):
            self.worker.wake()

    # -- stitching (frame-set thread) -----------------------------------------------------
    def _on_error(self, exc):
        self._error = f'{type(exc).__name__}: {exc}'
        if isinstance(exc, AccelcalError):
            self._warn_once(('error', str(exc)), f'cannot stitch: {exc}')
        else:
            self._warn_once(('crash', type(exc).__name__), f'stitching failed: {self._error}')

    def _stitch(self, frame_set):
        start = time.perf_counter()
        self.roi.submit(frame_set)  # the levelled views render in their own thread
        self.stitcher.rebuild_threshold_deg = self.params['rebuild_threshold_deg']
        # remap and publishing run in the render thread (the next set's lookup is
        # rebuilt meanwhile); bad input raises here, before anything is queued
        self.stitcher.submit(frame_set.roll_rad, frame_set.pitch_rad, frame_set.images,
                             lambda panorama: self._publish(panorama, frame_set.stamp_s,
                                                            start))

    def _publish(self, panorama, stamp_s, start):
        """Publish one panorama (render thread); errors are logged, not raised."""
        total_ns = int(round(stamp_s * 1e9))
        sec, nanosec = divmod(total_ns, 1_000_000_000)
        try:
            if self.publisher.get_subscription_count():
                self.publisher.publish(image_cdr(panorama, self.encoding, sec, nanosec,
                                                 self.params['frame_id']))
            if self.compressed is not None:
                self._publish_compressed(panorama, sec, nanosec)
        except Exception as exc:  # keep rendering; say what happened
            self._warn_once(('publish', type(exc).__name__),
                            f'publishing the panorama failed: {type(exc).__name__}: {exc}')
            return
        now = time.monotonic()
        self._published += 1
        self._process_s = time.perf_counter() - start
        self._latency_s = self.get_clock().now().nanoseconds * 1e-9 - stamp_s
        self._publish_times = [t for t in self._publish_times if t > now - 5.0] + [now]
        self.policy.status = 'publishing'

    def _publish_compressed(self, panorama, sec, nanosec):
        """JPEG of the panorama as image_transport's ``compressed`` sends it."""
        jpeg = encode_jpeg(panorama, self.params['jpeg_quality'], rgb=self.encoding == 'rgb8')
        msg = CompressedImage()
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
        msg.header.frame_id = self.params['frame_id']
        target = 'mono8' if self.encoding == 'mono8' else 'bgr8'
        msg.format = f'{self.encoding}; jpeg compressed {target}'
        msg.data = jpeg
        self.compressed.publish(msg)

    # -- diagnostics ----------------------------------------------------------------------
    def _publish_diagnostics(self):
        now = time.monotonic()
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        times = [t for t in self._publish_times if t > now - 5.0]
        fps = (len(times) - 1) / (times[-1] - times[0]) if len(times) > 1 \
            and times[-1] > times[0] else 0.0
        policy = self.policy
        main = DiagnosticStatus(name='stitcher: panorama', hardware_id='stitcher')
        recent_jump = policy.time_jumps and not times
        main.level = DiagnosticStatus.OK if policy.status == 'publishing' and times \
            else DiagnosticStatus.WARN
        main.message = policy.status if times or policy.status != 'publishing' else \
            'no panorama for 5 s'
        if recent_jump:
            main.message = f'{main.message} (after a time jump: {policy.last_jump})'
        main.values = [
            KeyValue(key='published', value=str(self._published)),
            KeyValue(key='rate_hz', value=f'{fps:.2f}'),
            KeyValue(key='latency_ms', value=f'{1e3 * self._latency_s:.1f}'),
            KeyValue(key='processing_ms', value=f'{1e3 * self._process_s:.1f}'),
            KeyValue(key='lookup_rebuilds', value=str(self.stitcher.rebuild_count)),
            KeyValue(key='last_rebuild_ms', value=f'{1e3 * self.stitcher.last_rebuild_s:.1f}'),
            KeyValue(key='time_jumps', value=str(policy.time_jumps)),
            KeyValue(key='rejected_attitudes', value=str(policy.rejected_attitudes)),
            KeyValue(key='last_time_jump', value=policy.last_jump or 'none'),
            KeyValue(key='last_error', value=self._error or 'none'),
        ]
        if self.inputs is not None:
            main.values.append(KeyValue(key='decode_ms', value=f'{self.inputs.decode_ms():.1f}'))
            main.values.append(KeyValue(key='decode_dropped',
                                        value=str(self.inputs.pool.replaced)))
        statuses = [main]
        for i, state in enumerate(policy.cameras(now)):
            cam = self.rig.cameras[i]
            status = DiagnosticStatus(name=f'stitcher: camera {cam.name}',
                                      hardware_id=self.topics[i])
            if state.age_s is None:
                status.level = DiagnosticStatus.WARN if not state.rejected else \
                    DiagnosticStatus.ERROR
                status.message = 'no frame received yet; sector black' if not \
                    state.rejected else f'all frames rejected: {state.reject_reason}'
            elif state.stalled:
                status.level = DiagnosticStatus.WARN
                status.message = f'stalled: no frame for {state.age_s:.1f} s; sector black'
            else:
                status.level = DiagnosticStatus.OK
                status.message = 'ok'
            status.values = [
                KeyValue(key='topic', value=self.topics[i]),
                KeyValue(key='frame_age_s',
                         value='inf' if state.age_s is None else f'{state.age_s:.2f}'),
                KeyValue(key='received_frames', value=str(state.received)),
                KeyValue(key='rejected_frames', value=str(state.rejected)),
            ]
            statuses.append(status)
        array.status = statuses
        self.diagnostics.publish(array)


def main(args=None):
    """Run the ``stitcher`` node (events executor: the least CPU per received frame)."""
    use_large_message_profile()  # frames and panoramas through shared memory
    return run(StitcherNode, args, executor='events')


if __name__ == '__main__':
    raise SystemExit(main())
