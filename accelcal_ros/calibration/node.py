"""
``calibration``: field calibration of the accelerometer as a ROS 2 node (thin wiring).

Subscribes ``imu/data_raw`` (sensor_msgs/Imu, m/s^2, sensor-data QoS). Services
(std_srvs/Trigger): ``calibration/start`` (new session), ``calibration/capture`` (take the
current still position now), ``calibration/finish`` (fit, save ``output_file``, apply to
the attitude node), ``calibration/cancel``. Publishes ``calibration/status``
(diagnostic_msgs/DiagnosticStatus, reliable, transient local) after every capture and
every ``status_period_s`` while a session runs, and with it ``calibration/coverage_markers``
(visualization_msgs/MarkerArray, same QoS, in the IMU messages' frame: every captured
direction, the directions still missing, the next suggested orientation;
:mod:`~accelcal_ros.calibration.markers_ros`). The session logic is the pure
:class:`~accelcal_ros.calibration.session.Calibrator`; parameters:
:data:`~accelcal_ros.calibration.params.CALIBRATION_PARAMS`.

``finish`` applies the new calibration to the running attitude node through its standard
``<attitude_node>/set_parameters`` service (asynchronously: the executor never blocks).
"""
import os

from accelcal_ros.calibration.params import CALIBRATION_PARAMS, calibrator_config
from accelcal_ros.calibration.session import Calibrator
from accelcal_ros.errors import AccelcalError
from accelcal_ros.rosutil.params import ParameterSet
from accelcal_ros.rosutil.qos import imu_subscription_qos
from accelcal_ros.rosutil.runner import run
from accelcal_ros.sensor.calibration_file import save_calibration
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rcl_interfaces.srv import SetParameters
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu
from std_msgs.msg import Header
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray


class CalibrationNode(Node):
    """Thin node around :class:`Calibrator`."""

    def __init__(self):
        super().__init__('calibration')
        self.params = ParameterSet(self, CALIBRATION_PARAMS)
        self.calibrator = Calibrator(calibrator_config(self.params.values))
        self.last_result = None
        self.last_event = ''
        self.saved_path = ''
        self._apply_clients = {}
        self.create_subscription(Imu, 'imu/data_raw', self._on_imu, imu_subscription_qos())
        # A late joiner (ros2 topic echo --once) gets the latest status only.
        status_qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.status_pub = self.create_publisher(DiagnosticStatus, 'calibration/status',
                                                status_qos)
        self.marker_pub = self.create_publisher(MarkerArray, 'calibration/coverage_markers',
                                                status_qos)
        self._frame_id = 'imu_link'
        self.create_service(Trigger, 'calibration/start', self._on_start)
        self.create_service(Trigger, 'calibration/capture', self._on_capture)
        self.create_service(Trigger, 'calibration/finish', self._on_finish)
        self.create_service(Trigger, 'calibration/cancel', self._on_cancel)
        self.create_timer(self.params['status_period_s'], self._on_timer)
        self._publish_status()
        self.get_logger().info('ready: call calibration/start, hold the sensor still in a '
                               'dozen orientations, then call calibration/finish')

    # -- samples ------------------------------------------------------------------------
    def _on_imu(self, msg):
        if not self.calibrator.active:
            return
        a = msg.linear_acceleration
        stamp = msg.header.stamp
        self._frame_id = msg.header.frame_id or self._frame_id
        g = STANDARD_GRAVITY_M_S2
        events = self.calibrator.add_sample(stamp.sec + stamp.nanosec * 1e-9,
                                            (a.x / g, a.y / g, a.z / g))
        if not events:
            return
        captured = False
        for event in events:
            self.last_event = event
            if event.startswith('rejected'):
                self.get_logger().warning(event)
            else:
                self.get_logger().info(event)
            captured = captured or event.startswith('captured')
        if captured:
            progress = self.calibrator.progress()
            self.get_logger().info(progress.text())
            self._publish_status()

    # -- services -----------------------------------------------------------------------
    def _on_start(self, request, response):
        self.calibrator.config = calibrator_config(self.params.values)
        try:
            self.calibrator.start()
        except AccelcalError as exc:
            return self._refuse(response, exc)
        return self._accept(
            response, f'calibration started ({self.calibrator.config.model} model): '
            f'hold the sensor still in at least {self.calibrator.needed} '
            'well spread orientations (auto capture '
            f'{"on" if self.calibrator.config.auto_capture else "off"})',
            event='session started')

    def _on_capture(self, request, response):
        try:
            cap = self.calibrator.capture_now()
        except AccelcalError as exc:
            return self._refuse(response, exc)
        return self._accept(response, f'captured position {cap.index} ({cap.samples} '
                            'samples so far; it keeps averaging until the sensor moves)')

    def _on_cancel(self, request, response):
        try:
            count = self.calibrator.cancel()
        except AccelcalError as exc:
            return self._refuse(response, exc)
        return self._accept(response, f'calibration cancelled; {count} positions discarded')

    def _on_finish(self, request, response):
        try:
            result = self.calibrator.finish(end=False)
        except AccelcalError as exc:
            return self._refuse(response, f'{exc}; the session stays open: capture more '
                                'positions and call calibration/finish again')
        path = os.path.expanduser(self.params['output_file'])
        try:
            save_calibration(path, result)
        except (OSError, AccelcalError) as exc:
            return self._refuse(response, f'fitted, but cannot write {path}: {exc}; set '
                                'output_file to a writable path and call finish again')
        self.calibrator.end()
        self.last_result, self.saved_path = result, path
        for warning in result.warnings:
            self.get_logger().warning(warning)
        applied = self._apply_to_attitude(result)
        return self._accept(response, f'{result.summary()}; saved to {path}; {applied}')

    def _accept(self, response, message, event=None):
        response.success = True
        response.message = message
        self.last_event = event or message
        self.get_logger().info(message)
        self._publish_status()
        return response

    def _refuse(self, response, exc):
        response.success = False
        response.message = str(exc)
        self.last_event = f'refused: {exc}'
        self.get_logger().warning(f'refused: {exc}')
        self._publish_status()
        return response

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
            self.last_event = f'calibration applied to "{name}"'
            self.get_logger().info(self.last_event)
            self._publish_status()

    # -- status -------------------------------------------------------------------------
    def _on_timer(self):
        if self.calibrator.active:
            self._publish_status()

    def _publish_status(self):
        progress = self.calibrator.progress()
        status = DiagnosticStatus(name=f'{self.get_name()}: accelerometer calibration',
                                  hardware_id='adxl345')
        values = {
            'active': str(progress.active).lower(),
            'model': self.calibrator.config.model,
            'positions': str(progress.positions),
            'positions_needed': str(progress.needed),
            'coverage_percent': f'{progress.coverage * 100:.0f}',
            'predicted_tilt_error_deg': ('' if progress.predicted_tilt_error_deg is None
                                         else f'{progress.predicted_tilt_error_deg:.4f}'),
            'hint': '; '.join(progress.hints),
            'still': str(progress.still).lower(),
            'rejected_samples': str(progress.rejected_samples),
            'last_event': self.last_event,
        }
        if progress.active:
            status.level = DiagnosticStatus.OK
            status.message = progress.text()
        elif self.last_result is not None:
            r = self.last_result
            status.level = DiagnosticStatus.WARN if r.warnings else DiagnosticStatus.OK
            status.message = f'last calibration: {r.summary()}'
            values.update({
                'residual_rms_mg': f'{r.residual_rms_g * 1e3:.3f}',
                'holdout_rms_mg': ('' if r.holdout_rms_g is None
                                   else f'{r.holdout_rms_g * 1e3:.3f}'),
                'fit_positions': str(r.positions),
                'fit_predicted_tilt_error_deg': f'{r.predicted_tilt_error_deg:.4f}',
                'scale': ' '.join(f'{v:.6f}' for v in r.sensor_model.scale),
                'bias_g': ' '.join(f'{v:.6f}' for v in r.sensor_model.bias),
                'misalignment_rad': ' '.join(f'{v:.6f}' for v in r.sensor_model.misalignment),
                'output_file': self.saved_path,
            })
        else:
            status.level = DiagnosticStatus.OK
            status.message = 'idle: call calibration/start'
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        self.status_pub.publish(status)
        self._publish_markers(progress)

    def _publish_markers(self, progress):
        from accelcal_ros.calibration.markers_ros import coverage_markers

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
