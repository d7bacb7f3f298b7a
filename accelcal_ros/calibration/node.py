"""
``calibration``: field calibration of the accelerometer as a ROS 2 node (thin wiring).

Subscribes ``imu/data_raw`` (sensor_msgs/Imu, m/s^2, sensor-data QoS). Services
(std_srvs/Trigger): ``calibration/start`` (new session), ``calibration/capture`` (take the
current still position now), ``calibration/finish`` (fit, save ``output_file``, apply to
the attitude node), ``calibration/cancel``. Publishes ``calibration/status``
(diagnostic_msgs/DiagnosticStatus, reliable, transient local) after every capture and
every ``status_period_s`` while a session runs, and ``/diagnostics``: the interface every
calibration node shares (:mod:`accelcal_ros.session_interface`). With every status it
publishes ``calibration/coverage_markers`` (visualization_msgs/MarkerArray, same QoS, in
the IMU messages' frame: every captured direction, the directions still missing, the
next suggested orientation; :mod:`~accelcal_ros.calibration.markers_ros`). The session
logic is the pure
:class:`~accelcal_ros.calibration.session.Calibrator`; parameters:
:data:`~accelcal_ros.calibration.params.CALIBRATION_PARAMS`.

The session settings (``model``, ``auto_capture``, the still detector's thresholds,
``min_positions``, ...) are read at ``calibration/start``: a change takes effect at the
next session. ``status_period_s`` takes effect at once.

Samples that cannot be used (NaN/infinite, or saturated: beyond ``saturation_g``) are
counted in one :class:`~accelcal_ros.rosutil.drops.DropCounter` (``/diagnostics`` status
``calibration: dropped messages``, kinds ``imu_nan`` and ``imu_saturated``; a header
stamp of 0 or not after the previous one, ``imu_unstamped`` and ``imu_out_of_order``,
skipped; stamps jumping back by 1 s or more, ``imu_time_jump``, counted and used: the dwell
ends there) and logged at most every 10 s; samples outside a session are not read (not a
drop). A capture with no usable sample since ``calibration/start`` says so and names the
topic.

``finish`` applies the new calibration to the running attitude node through its standard
``<attitude_node>/set_parameters`` service (asynchronously: the executor never blocks).
"""
import os

from accelcal_ros.calibration.params import CALIBRATION_PARAMS, calibrator_config
from accelcal_ros.calibration.session import Calibrator
from accelcal_ros.errors import AccelcalError, CalibrationError, FileWriteError
from accelcal_ros.rosutil.calibration_interface import CalibrationInterface
from accelcal_ros.rosutil.drops import DropCounter
from accelcal_ros.rosutil.params import ParameterSet
from accelcal_ros.rosutil.qos import imu_subscription_qos
from accelcal_ros.rosutil.runner import run
from accelcal_ros.rosutil.stamps import JUMPED_BACK, StampOrder, USE
from accelcal_ros.sensor.calibration_file import save_calibration
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
from accelcal_ros.session_interface import no_samples_reason, OK, SessionProgress, WARN
from rcl_interfaces.srv import SetParameters
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray


class CalibrationNode(Node):
    """Thin node around :class:`Calibrator`, behind the shared calibration interface."""

    def __init__(self):
        super().__init__('calibration')
        self.params = ParameterSet(self, CALIBRATION_PARAMS, self._on_change)
        self.calibrator = Calibrator(calibrator_config(self.params.values))
        self.last_result = None
        self.saved_path = ''
        self._apply_clients = {}
        self.drops = DropCounter(self)
        self._rejected_seen = (0, 0)
        self._stamp_order = StampOrder()
        self._session_samples = self._skips_at_start = 0
        self._imu_sub = self.create_subscription(Imu, 'imu/data_raw', self._on_imu,
                                                 imu_subscription_qos())
        # markers first: the interface publishes the first status (and with it markers)
        marker_qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.marker_pub = self.create_publisher(MarkerArray, 'calibration/coverage_markers',
                                                marker_qos)
        self._frame_id = 'imu_link'
        self.session = CalibrationInterface(
            self, self, 'accelerometer calibration', 'adxl345',
            'hold the sensor still in a new orientation (auto capture) or call '
            'calibration/capture while it rests', self.params['status_period_s'])
        self.get_logger().info('ready: call calibration/start, hold the sensor still in a '
                               'dozen orientations, then call calibration/finish')

    def _on_change(self, name, value):
        if name == 'status_period_s':
            self.session.set_period(value)

    # -- samples ------------------------------------------------------------------------
    def _on_imu(self, msg):
        if not self.calibrator.active:
            return
        a = msg.linear_acceleration
        stamp = msg.header.stamp
        t = stamp.sec + stamp.nanosec * 1e-9
        order = self._stamp_order.check(t)
        if order is not USE:
            self.drops.drop('imu_' + order, self._stamp_order.reason(
                order, 'imu/data_raw', 'the current still dwell ends there'))
            if order != JUMPED_BACK:
                return
        self._session_samples += 1
        self._frame_id = msg.header.frame_id or self._frame_id
        g = STANDARD_GRAVITY_M_S2
        events = self.calibrator.add_sample(t, (a.x / g, a.y / g, a.z / g))
        detector = self.calibrator.detector
        rejected = (detector.rejected_nan, detector.rejected_saturated)
        if rejected != self._rejected_seen:
            self._count_rejected(rejected)
        for event in events:
            if event.startswith('rejected'):
                continue   # counted and logged (throttled) by the DropCounter
            self.session.event(event)
            if event.startswith('captured'):
                self.get_logger().info(self.calibrator.progress().text())

    def _count_rejected(self, rejected):
        """Count the samples the still detector rejected since the last call."""
        seen, self._rejected_seen = self._rejected_seen, rejected
        new = [r - s if r >= s else r for r, s in zip(rejected, seen)]  # a new session: 0
        saturation = self.calibrator.config.saturation_g
        self.drops.drop('imu_nan', 'imu/data_raw sample with NaN or infinity not used',
                        new[0])
        self.drops.drop('imu_saturated', 'imu/data_raw sample saturated (beyond '
                        f'{saturation:g} g on an axis) not used', new[1])

    # -- the session (backend of CalibrationInterface) -------------------------------------
    def begin(self):
        """Open a session with the current parameters."""
        self.calibrator.config = calibrator_config(self.params.values)
        self.calibrator.start()
        self._session_samples = 0
        self._skips_at_start = self._stamp_order.skipped
        return (f'calibration started ({self.calibrator.config.model} model): hold the '
                f'sensor still in at least {self.calibrator.needed} well spread '
                'orientations (auto capture '
                f'{"on" if self.calibrator.config.auto_capture else "off"})')

    def capture(self):
        """Capture the current still dwell (CalibrationError with the reason)."""
        if self.calibrator.active and not self._session_samples:
            skipped = self._stamp_order.skipped - self._skips_at_start
            raise CalibrationError(no_samples_reason(self._imu_sub.topic_name, skipped))
        cap = self.calibrator.capture_now()
        return (f'captured position {cap.index} ({cap.samples} samples so far; it keeps '
                'averaging until the sensor moves)')

    def discard(self):
        """Drop the session."""
        return self.calibrator.cancel()

    def output_file(self):
        """Return the calibration file finish writes (~ expanded)."""
        return os.path.expanduser(self.params['output_file'])

    def solve(self):
        """Fit, save the file, apply it to the attitude node; the session then ends."""
        result = self.calibrator.finish(end=False)
        path = self.output_file()
        try:
            save_calibration(path, result)
        except (OSError, AccelcalError) as exc:
            raise FileWriteError(f'fitted, but cannot write {path}: {exc}; set output_file '
                                 'to a writable path') from exc
        self.calibrator.end()
        self.last_result, self.saved_path = result, path
        for warning in result.warnings:
            self.get_logger().warning(warning)
        applied = self._apply_to_attitude(result)
        return f'{result.summary()}; saved to {path}; {applied}'

    # -- applying the calibration ---------------------------------------------------------
    def _apply_to_attitude(self, result):
        name = self.params['attitude_node'].strip()
        if not name:
            return 'not applied (attitude_node is empty)'
        service = f'{name}/set_parameters'
        client = self._apply_clients.get(service)
        if client is None:
            client = self.create_client(SetParameters, service)
            self._apply_clients[service] = client
        if not client.service_is_ready():
            text = (f'attitude node "{name}" not found: load the file with '
                    f'ros2 param set /{name.lstrip("/")} calibration_file {self.saved_path}')
            self.get_logger().warning(text)
            return text
        sm = result.sensor_model
        tilt_std_deg = float(result.predicted_tilt_error_deg / 1.96)
        values = {'calibration.model': result.model,
                  'calibration.scale': [float(v) for v in sm.scale],
                  'calibration.bias': [float(v) for v in sm.bias],
                  'calibration.misalignment': [float(v) for v in sm.misalignment],
                  'calibration.tilt_std_deg': tilt_std_deg}
        request = SetParameters.Request()
        request.parameters = [Parameter(k, value=v).to_parameter_msg()
                              for k, v in values.items()]
        future = client.call_async(request)
        future.add_done_callback(lambda f: self._on_applied(f, name))
        return f'applying to node "{name}"'

    def _on_applied(self, future, name):
        try:
            results = future.result().results
        except Exception as exc:  # noqa: B902 - any transport failure is reported
            self.get_logger().warning(f'could not apply the calibration to "{name}": {exc}')
            return
        failed = [r.reason for r in results if not r.successful]
        if failed:
            self.get_logger().warning(f'"{name}" rejected the calibration: {"; ".join(failed)}')
        else:
            self.session.event(f'calibration applied to "{name}"')

    # -- status -------------------------------------------------------------------------
    def progress(self, active):
        """Return the :class:`SessionProgress` of the session, or of the last result."""
        progress = self.calibrator.progress()
        extra = {'model': self.calibrator.config.model, 'still': str(progress.still).lower(),
                 'rejected_samples': str(progress.rejected_samples)}
        if progress.active:
            return SessionProgress(progress.positions, progress.needed, progress.coverage,
                                   progress.predicted_tilt_error_deg,
                                   '; '.join(progress.hints), extra, progress.text())
        r = self.last_result
        if r is None:
            return SessionProgress(0, progress.needed, extra=extra)
        extra.update({
            'residual_rms_mg': f'{r.residual_rms_g * 1e3:.3f}',
            'holdout_rms_mg': '' if r.holdout_rms_g is None else f'{r.holdout_rms_g * 1e3:.3f}',
            'scale': ' '.join(f'{v:.6f}' for v in r.sensor_model.scale),
            'bias_g': ' '.join(f'{v:.6f}' for v in r.sensor_model.bias),
            'misalignment_rad': ' '.join(f'{v:.6f}' for v in r.sensor_model.misalignment)})
        return SessionProgress(r.positions, progress.needed, None, r.predicted_tilt_error_deg,
                               'call calibration/start for a new calibration', extra,
                               f'last calibration: {r.summary()}',
                               WARN if r.warnings else OK)

    def status_published(self, active):
        """Publish the coverage markers beside each status (the interface's hook)."""
        from accelcal_ros.calibration.markers_ros import coverage_markers

        progress = self.calibrator.progress()
        header = Header(stamp=self.get_clock().now().to_msg(), frame_id=self._frame_id)
        captured = self.calibrator.captured_means()[0] if progress.active else []
        self.marker_pub.publish(coverage_markers(
            header, captured, self.calibrator.config.coverage_radius_deg,
            bool(progress.active and progress.hints)))


def main(args=None):
    """Run the ``calibration`` node."""
    return run(CalibrationNode, args, executor='events')


if __name__ == '__main__':
    raise SystemExit(main())
