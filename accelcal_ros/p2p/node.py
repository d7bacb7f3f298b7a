"""
``p2p``: camera pose from two emitters and the accelerometer's vertical (thin ROS wiring).

Subscribes (relative; sensor-data QoS, which also receives from reliable publishers, except
``image``: reliable keep-last 2 by default, so that every frame of a reliable camera driver
arrives whole and a slow node only drops older frames; ``image_qos:=sensor_data`` for
best-effort drivers): ``image`` (sensor_msgs/Image in any encoding of
:mod:`accelcal_ros.rosutil.images`; received raw, the pixels read as a numpy view on the
received buffer, no copy for mono8; ``image_transport:=compressed``: ``image/compressed``,
sensor_msgs/CompressedImage as image_transport writes it, decoded off the executor thread
by :mod:`accelcal_ros.rosutil.image_input`, undecodable frames counted in
``undecodable_frames`` and skipped), ``camera_info``
(sensor_msgs/CameraInfo: K, D and distortion_model) and ``attitude``
(geometry_msgs/Vector3Stamped: x = roll, y = pitch of the IMU in rad, REP-103, as the
``attitude`` node publishes it; matched to each image by stamp).

Publishes ``pose`` (geometry_msgs/PoseStamped: the object in the camera optical frame,
``X_cam = R X_obj + t``, frame_id and stamp of the image), ``yaw``
(geometry_msgs/Vector3Stamped, the image's header; ``vector.z`` = the heading of the
optical axis about the object's vertical, rad; x = y = 0, as ``attitude`` carries roll
and pitch in x and y;
:func:`accelcal_ros.p2p.solver.yaw_from_rotation`), ``pose_candidates``
(geometry_msgs/PoseArray: every valid solution, also when ambiguous) and
``/diagnostics`` (the reason when there is no pose, detection quality). Every dropped
input is counted in one :class:`~accelcal_ros.rosutil.drops.DropCounter` (``p2p: dropped
messages``) and logged at most every 10 s per kind: ``images`` (unsupported encoding,
bad buffer), ``images_undecodable``, ``images_replaced`` (a compressed frame replaced
by a newer one before it was decoded), ``images_size`` (not camera_info's size),
``images_no_attitude`` (no attitude within ``attitude_tolerance_s``), ``attitudes`` (not
finite, or outside roll +-pi, pitch +-pi/2) and ``camera_info`` (unusable K/D). The logic is
:class:`accelcal_ros.p2p.pipeline.P2PPipeline`; parameters:
:data:`accelcal_ros.p2p.params.P2P_PARAMS`.
"""
import math
import threading

from accelcal_ros.errors import AccelcalError, InputError
from accelcal_ros.p2p.params import P2P_PARAMS
from accelcal_ros.p2p.pipeline import P2PPipeline
from accelcal_ros.rosutil.dds import use_large_message_profile
from accelcal_ros.rosutil.diagnostics import PeriodicTimer
from accelcal_ros.rosutil.drops import DropCounter
from accelcal_ros.rosutil.image_input import compressed_topic, CompressedInputs
from accelcal_ros.rosutil.images import convert_color, image_array, parse_image_cdr
from accelcal_ros.rosutil.params import ParameterSet
from accelcal_ros.rosutil.runner import run
from accelcal_ros.rosutil.stamps import stamp_to_seconds
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Pose, PoseArray, PoseStamped, Vector3Stamped
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header


def _pose_msg(solution):
    pose = Pose()
    t = solution.translation
    pose.position.x, pose.position.y, pose.position.z = float(t[0]), float(t[1]), float(t[2])
    q = Rotation.from_matrix(solution.rotation).as_quat()
    o = pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in q)
    return pose


class P2PNode(Node):
    """Thin node around :class:`~accelcal_ros.p2p.pipeline.P2PPipeline`."""

    def __init__(self):
        super().__init__('p2p')
        self._lock = threading.Lock()
        self.params = ParameterSet(self, P2P_PARAMS, on_change=self._on_change)
        self.pipeline = P2PPipeline(self.params.values)
        self.pose_pub = self.create_publisher(PoseStamped, 'pose', 10)
        self.yaw_pub = self.create_publisher(Vector3Stamped, 'yaw', 10)
        self.candidates_pub = self.create_publisher(PoseArray, 'pose_candidates', 10)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.drops = DropCounter(self)
        qos = qos_profile_sensor_data
        image_qos = qos if self.params['image_qos'] == 'sensor_data' else QoSProfile(
            depth=2, reliability=ReliabilityPolicy.RELIABLE)
        self._qos_warned = False
        self.inputs = None
        if self.params['image_transport'] == 'compressed':
            self.inputs = CompressedInputs(
                self, [compressed_topic(self, 'image')], image_qos,
                lambda i, raw, grey, enc: self._on_decoded(raw, grey, enc),
                lambda i, reason: self._on_undecodable(reason),
                on_replaced=lambda i: self.drops.drop(
                    'images_replaced', 'a compressed frame replaced by a newer one before '
                    'it was decoded (decoding falls behind; the newest frame is kept)'),
                events=lambda i: SubscriptionEventCallbacks(
                    incompatible_qos=self._incompatible))
        else:
            self.create_subscription(
                Image, 'image', self._on_image, image_qos, raw=True,
                event_callbacks=SubscriptionEventCallbacks(incompatible_qos=self._incompatible))
        self.create_subscription(CameraInfo, 'camera_info', self._on_camera_info, qos)
        self.create_subscription(Vector3Stamped, 'attitude', self._on_attitude, qos)
        self._camera_info_key = None
        self._counts = {'images': 0, 'poses': 0, 'no_pose': 0, 'ambiguous_resolved': 0,
                        'attitudes_rejected': 0}
        if self.inputs is not None:
            self._counts['undecodable_frames'] = 0
        self._last_reason = 'no image received yet'
        self._logged_reason = None
        self._last_quality = {}
        self._last_result = None
        self._diag_timer = PeriodicTimer(self, self.params['diagnostics_period_s'],
                                         self._publish_diagnostics)
        self.get_logger().info(
            f'p2p: emitters M1 {self.pipeline.points[0].tolist()} M2 '
            f'{self.pipeline.points[1].tolist()} m; waiting for {self._topic("image")}, '
            f'{self._topic("camera_info")} and {self._topic("attitude")}')

    def _topic(self, name):
        return self.resolve_topic_name(name)

    def close(self):
        """Stop the decode threads of the compressed input (the runner calls this)."""
        if self.inputs is not None:
            self.inputs.close()

    def _on_change(self, name, value):
        if name == 'diagnostics_period_s':
            self._diag_timer.set_period(value)
        with self._lock:
            self.pipeline.configure({name: value})
        if name == 'order' or name == 'emitters':
            self.pipeline.last_pose = None

    def _on_camera_info(self, msg):
        key = (tuple(msg.k), tuple(msg.d), msg.distortion_model, msg.width, msg.height)
        if key == self._camera_info_key:
            return
        self._camera_info_key = key
        with self._lock:
            reason = self.pipeline.set_camera_info(msg.k, msg.d, msg.distortion_model,
                                                   msg.width, msg.height)
        if reason:
            self.drops.drop('camera_info', reason)
            self._note(reason, log=False)
        else:
            self.get_logger().info(f'camera_info: {msg.width}x{msg.height}, fx {msg.k[0]:.1f}, '
                                   f'D {msg.distortion_model or "none"} '
                                   f'{[round(v, 5) for v in msg.d]}')

    def _on_attitude(self, msg):
        try:
            with self._lock:
                results = self.pipeline.add_attitude(stamp_to_seconds(msg.header.stamp),
                                                     msg.vector.x, msg.vector.y)
        except InputError as exc:  # not an attitude (pitch 4 rad, roll 1e300): counted
            self._counts['attitudes_rejected'] += 1
            self.drops.drop('attitudes', f'attitude rejected: {exc}')
            self._note('attitude rejected: not finite or outside roll +-pi, pitch +-pi/2 '
                       '(counted in attitudes_rejected)', log=False)
            return
        for result in results:
            self._publish(result)

    def _incompatible(self, event):
        if not self._qos_warned:
            self._qos_warned = True
            self.get_logger().warning(
                f'{self._topic("image")}: a publisher with incompatible QoS (best effort?) '
                'is ignored; set image_qos:=sensor_data for best-effort camera drivers')

    def _on_image(self, data):
        """Raw (serialized) image: header fields parsed, pixels viewed in place."""
        self._counts['images'] += 1
        try:
            raw = parse_image_cdr(data)
            enc = raw.encoding.lower()
            grey = image_array(raw.height, raw.width, raw.encoding, raw.is_bigendian,
                               raw.step, raw.data, raw.offset, length=raw.length,
                               want=None if enc in ('mono8', '8uc1') else 'mono8',
                               topic=self._topic('image'))
        except InputError as exc:
            self._counts['no_pose'] += 1
            self.drops.drop('images', f'image rejected: {exc}')
            self._note(f'image rejected: {exc}', log=False)
            return
        self._process(raw, grey)

    def _on_decoded(self, raw, image, encoding):
        """Take a decoded compressed frame (decode thread): grey, then the pipeline."""
        self._counts['images'] += 1
        self._process(raw, convert_color(image, encoding, 'mono8'))

    def _on_undecodable(self, reason):
        """Count and skip a compressed frame that does not decode (decode thread)."""
        self._counts['images'] += 1
        self._counts['undecodable_frames'] += 1
        self._last_reason = f'frame skipped: {reason}'
        self.drops.drop('images_undecodable', f'frame skipped: {reason}')

    def _process(self, raw, grey):
        """Run the pipeline on a grey image of ``raw``'s stamp and frame; publish."""
        header = Header(frame_id=raw.frame_id)
        header.stamp.sec, header.stamp.nanosec = raw.stamp_sec, raw.stamp_nanosec
        with self._lock:
            try:
                results = self.pipeline.add_image(raw.stamp_s, raw.frame_id, grey,
                                                  tag=header)
            except AccelcalError as exc:
                self._counts['no_pose'] += 1
                self.drops.drop('images', f'image rejected: {exc}')
                self._note(f'image rejected: {exc}', log=False)
                return
        for result in results:
            self._publish(result)

    def _publish(self, result):
        self._last_result = result
        if result.detection is not None:
            self._last_quality = result.detection.quality()
        header = result.tag
        if result.candidates:
            array = PoseArray(header=header, poses=[_pose_msg(s) for s in result.candidates])
            self.candidates_pub.publish(array)
        if result.solution is None:
            self._counts['no_pose'] += 1
            if result.dropped:
                self.drops.drop(result.dropped, f'image dropped: {result.reason}')
            self._note(result.reason, log=not result.dropped)
            return
        self._counts['poses'] += 1
        if result.resolved_by_continuity:
            self._counts['ambiguous_resolved'] += 1
        self.pose_pub.publish(PoseStamped(header=header, pose=_pose_msg(result.solution)))
        yaw = Vector3Stamped(header=header)
        yaw.vector.z = float(result.solution.yaw)
        self.yaw_pub.publish(yaw)
        if self._last_reason:
            self.get_logger().info('pose available again')
        self._last_reason = ''
        self._logged_reason = None

    def _note(self, reason, log=True):
        """Record why there is no pose; log it once per change (not per frame)."""
        self._last_reason = reason
        if reason != self._logged_reason:
            self._logged_reason = reason
            if log:
                self.get_logger().warning(f'no pose: {reason}')
            self._publish_diagnostics()

    def _publish_diagnostics(self):
        status = DiagnosticStatus(name=f'{self.get_name()}: P2P positioning',
                                  hardware_id='p2p')
        if self._last_reason:
            status.level, status.message = DiagnosticStatus.WARN, self._last_reason
        else:
            status.level, status.message = DiagnosticStatus.OK, 'pose'
        values = {k: str(v) for k, v in self._counts.items()}
        values.update({k: str(v) for k, v in self._last_quality.items()})
        result = self._last_result
        if result is not None and result.solution is not None:
            values['range_m'] = f'{result.solution.range_m:.4f}'
            values['yaw_deg'] = f'{math.degrees(result.solution.yaw):.3f}'
            values['solutions'] = str(len(result.candidates))
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)


def main(args=None):
    """Run the ``p2p`` node (events executor: the least CPU per received frame)."""
    use_large_message_profile()  # frames and panoramas through shared memory
    return run(P2PNode, args, executor='events')


if __name__ == '__main__':
    raise SystemExit(main())
