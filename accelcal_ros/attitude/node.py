"""
``attitude``: calibrated roll and pitch from ``imu/data_raw`` (thin ROS wiring).

Subscribes ``imu/data_raw`` (sensor_msgs/Imu, m/s^2, sensor-data QoS). Publishes, with
the input's header (stamp and frame_id):

* ``attitude`` (geometry_msgs/Vector3Stamped): x = roll, y = pitch, z = 0, rad, REP-103;
* ``imu/data`` (sensor_msgs/Imu): calibrated linear acceleration (m/s^2), orientation
  with yaw 0 (``Ry(pitch) Rx(roll)``), orientation covariance from the noise and the
  calibration's uncertainty (roll, pitch; yaw variance ``yaw_variance``), angular velocity
  covariance[0] = -1 (not provided). While the sensor accelerates (| |f| - 1 g | above
  ``accel_threshold_g``) the last good tilt is held and its covariance inflated.

The calibration comes from ``calibration_file`` or from the ``calibration.*`` parameters,
both settable at run time (``ros2 param set``, or the calibration node's finish). A bad
file or value is rejected with the reason and the last good calibration stays in use.
A ``calibration_file`` that does not exist yet (the node started before the calibration
was run) is a warning, given once: the node runs uncalibrated, checks every second and
loads the file when it appears (or uses a calibration pushed in the meantime).

Impossible input (NaN/infinite, a zero vector, a magnitude beyond any accelerometer such
as 1e300) publishes nothing: it is skipped, counted per reason in ``/diagnostics``
(``attitude: tilt``, once a second, with samples in and out) and logged at most every
10 s. Per sample the callback only assigns plain floats into pre-built messages.
Core: :class:`~accelcal_ros.sensor.tilt.TiltEstimator`.
"""
import math
import os

from accelcal_ros.attitude.params import ATTITUDE_PARAMS
from accelcal_ros.errors import AccelcalError, InputError
from accelcal_ros.rosutil.params import ParameterSet
from accelcal_ros.rosutil.qos import imu_subscription_qos
from accelcal_ros.rosutil.runner import run
from accelcal_ros.sensor.calibration_file import load_calibration
from accelcal_ros.sensor.datasheet import datasheet_noise_std_g
from accelcal_ros.sensor.model import SensorModel
from accelcal_ros.sensor.tilt import quaternion_from_roll_pitch, TiltEstimator
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Vector3Stamped
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Imu


DIAGNOSTICS_PERIOD_S = 1.0
"""Period of the /diagnostics status and of the check for a missing calibration file (s)."""


class AttitudeNode(Node):
    """Thin node around :class:`TiltEstimator`."""

    def __init__(self):
        super().__init__('attitude')
        self.params = ParameterSet(self, ATTITUDE_PARAMS, on_change=self._on_change)
        values = self.params.values
        self.estimator = TiltEstimator(time_constant_s=values['time_constant_s'],
                                       accel_threshold_g=values['accel_threshold_g'],
                                       max_hold_s=values['max_hold_s'])
        self._pending = {}
        self._rate_dt = None
        self._last_stamp = None
        self._noise_rate = None
        self._fixed_noise = bool(values['noise_std_g'])
        self._received = 0
        self._published = 0
        self._skipped = {'NaN': 0, 'zero': 0, 'out of range': 0}
        self._calibration_source = 'calibration.* parameters'
        self._waiting_for_file = ''
        self.estimator.set_calibration(*self._model_from_values(values))
        path = values['calibration_file']
        if path and not os.path.exists(os.path.expanduser(path)):
            self._waiting_for_file = path
            self._calibration_source = 'none yet (waiting for the calibration file)'
            self.get_logger().warning(
                f'calibration file {path} does not exist yet: running uncalibrated until '
                'it appears (checked every second) or a calibration is pushed')
        elif path:
            try:
                self._load_file(path)
            except AccelcalError as exc:
                self.get_logger().error(f'{exc}; running with the calibration.* values '
                                        '(uncalibrated unless set)')
        elif values['calibration.scale'] == [1.0, 1.0, 1.0] \
                and values['calibration.bias'] == [0.0, 0.0, 0.0]:
            self.get_logger().warning('no calibration: set calibration_file (or run the '
                                      'calibration node) for accurate roll and pitch')
        self.attitude_pub = self.create_publisher(Vector3Stamped, 'attitude',
                                                  qos_profile_sensor_data)
        self.imu_pub = self.create_publisher(Imu, 'imu/data', qos_profile_sensor_data)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._out_att = Vector3Stamped()
        self._out_imu = Imu()
        self._out_imu.angular_velocity_covariance[0] = -1.0
        self._out_imu.orientation_covariance[8] = float(values['yaw_variance'])
        self._fcov_source = None
        self.create_subscription(Imu, 'imu/data_raw', self._on_imu, imu_subscription_qos())
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._on_timer)

    # -- calibration ----------------------------------------------------------------------
    def _model_from_values(self, values):
        # calibration.model is informational: the misalignment is used as given (0 for
        # a diagonal calibration), so a request may set the values in any order.
        try:
            sensor_model = SensorModel(values['calibration.scale'], values['calibration.bias'],
                                       values['calibration.misalignment'])
        except AccelcalError as exc:
            raise InputError(str(exc)) from None
        return sensor_model, math.radians(values['calibration.tilt_std_deg'])

    def _load_file(self, path):
        record = load_calibration(os.path.expanduser(path))
        tilt_std = record.predicted_tilt_error_deg
        tilt_std_rad = math.radians(tilt_std / 1.96) if math.isfinite(tilt_std) else 0.0
        self.estimator.set_calibration(record.sensor_model, tilt_std_rad)
        self._waiting_for_file = ''
        self._calibration_source = f'file {path}'
        self.get_logger().info(
            f'loaded {record.model} calibration from {path}: scale '
            f'{record.sensor_model.scale.round(5).tolist()}, bias '
            f'{record.sensor_model.bias.round(5).tolist()} g')

    def _on_change(self, name, value):
        """Apply accepted run-time changes; raise InputError to reject one."""
        if name == 'calibration_file':
            if value:
                try:
                    self._load_file(value)
                except AccelcalError as exc:
                    self.get_logger().error(f'{exc}; keeping the last good calibration')
                    raise InputError(f'{exc}; the last good calibration is kept') from None
            else:   # empty: the calibration.* values (also how a rejected request undoes)
                self._waiting_for_file = ''
                merged = dict(self.params.values)
                merged.update(self._pending)
                self.estimator.set_calibration(*self._model_from_values(merged))
                self._calibration_source = 'calibration.* parameters'
        elif name.startswith('calibration.'):
            merged = dict(self.params.values)
            merged.update(self._pending)
            merged[name] = value
            sensor_model, tilt_std = self._model_from_values(merged)
            self._pending[name] = value
            self.estimator.set_calibration(sensor_model, tilt_std)
            self._waiting_for_file = ''
            self._calibration_source = 'calibration.* parameters'
        elif name == 'yaw_variance':
            self._out_imu.orientation_covariance[8] = float(value)
        elif name == 'time_constant_s':
            self.estimator.time_constant_s = value
            self.estimator.reset()
        elif name == 'accel_threshold_g':
            self.estimator.accel_threshold_g = value
        elif name == 'max_hold_s':
            self.estimator.max_hold_s = value
        elif name == 'noise_std_g':
            if value:
                self.estimator.set_noise(value)
            self._fixed_noise = bool(value)
            self._noise_rate = None

    # -- samples ----------------------------------------------------------------------------
    def _update_noise(self, stamp):
        """Follow the measured sample rate with the datasheet noise (noise_std_g empty)."""
        if self._last_stamp is not None and stamp > self._last_stamp:
            dt = stamp - self._last_stamp
            self._rate_dt = dt if self._rate_dt is None else 0.99 * self._rate_dt + 0.01 * dt
        self._last_stamp = stamp
        if self._fixed_noise or self._rate_dt is None:
            return
        rate = 1.0 / self._rate_dt
        if self._noise_rate is None or abs(rate - self._noise_rate) > 0.1 * self._noise_rate:
            self._noise_rate = rate
            self.estimator.set_noise(datasheet_noise_std_g(rate))

    def _on_imu(self, msg):
        self._received += 1
        if self._pending:
            self._pending.clear()
            v = self.params.values
            self.get_logger().info(
                f'calibration set: {v["calibration.model"]}, scale '
                f'{[round(x, 5) for x in v["calibration.scale"]]}, bias '
                f'{[round(x, 5) for x in v["calibration.bias"]]} g, misalignment '
                f'{[round(x, 6) for x in v["calibration.misalignment"]]} rad')
        a = msg.linear_acceleration
        header = msg.header
        stamp = header.stamp.sec + header.stamp.nanosec * 1e-9
        self._update_noise(stamp)
        g = STANDARD_GRAVITY_M_S2
        est = self.estimator.update(stamp, (a.x / g, a.y / g, a.z / g))
        if est is None:
            self._skip(self.estimator.last_rejection)
            return
        att = self._out_att
        att.header = header
        att.vector.x, att.vector.y = est.roll, est.pitch
        self.attitude_pub.publish(att)
        imu = self._out_imu
        imu.header = header
        o = imu.orientation
        o.x, o.y, o.z, o.w = quaternion_from_roll_pitch(est.roll, est.pitch)
        c00, c01, c11 = est.cov
        cov = imu.orientation_covariance
        cov[0], cov[1], cov[3], cov[4] = c00, c01, c01, c11
        fx, fy, fz = est.force
        lin = imu.linear_acceleration
        lin.x, lin.y, lin.z = fx * g, fy * g, fz * g
        source = self.estimator.force_covariance_list_g2
        if source is not self._fcov_source:   # changes with the calibration or the noise
            self._fcov_source = source
            imu.linear_acceleration_covariance = [v * g * g for v in source]
        self.imu_pub.publish(imu)
        self._published += 1

    def _skip(self, reason):
        """Count an impossible sample and say so, at most every 10 s."""
        self._skipped[reason] = self._skipped.get(reason, 0) + 1
        self.get_logger().warning(
            f'imu/data_raw sample skipped ({reason}: a reading with no usable direction); '
            f'skipped so far: {self._skipped}', throttle_duration_sec=10.0)

    def _on_timer(self):
        path = self._waiting_for_file
        if path and os.path.exists(os.path.expanduser(path)):
            try:
                self._load_file(path)
            except AccelcalError as exc:
                self._waiting_for_file = ''
                self.get_logger().error(f'{exc}; running uncalibrated (set calibration_file '
                                        'again once it is fixed)')
        self._publish_diagnostics()

    def _publish_diagnostics(self):
        status = DiagnosticStatus(name=f'{self.get_name()}: tilt',
                                  hardware_id='accelerometer')
        skipped = sum(self._skipped.values())
        if self._waiting_for_file:
            status.level = DiagnosticStatus.WARN
            status.message = (f'uncalibrated: waiting for {self._waiting_for_file}')
        elif not self.estimator.calibrated:
            status.level, status.message = DiagnosticStatus.WARN, 'uncalibrated'
        elif skipped:
            status.level = DiagnosticStatus.WARN
            status.message = f'{skipped} impossible samples skipped'
        else:
            status.level, status.message = DiagnosticStatus.OK, 'publishing'
        values = {'samples_received': str(self._received),
                  'samples_published': str(self._published),
                  'skipped_nan': str(self._skipped.get('NaN', 0)),
                  'skipped_zero': str(self._skipped.get('zero', 0)),
                  'skipped_out_of_range': str(self._skipped.get('out of range', 0)),
                  'calibrated': str(self.estimator.calibrated).lower(),
                  'calibration_source': self._calibration_source}
        if self._rate_dt:
            values['rate_hz_measured'] = f'{1.0 / self._rate_dt:.2f}'
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)


def main(args=None):
    """Run the ``attitude`` node."""
    return run(AttitudeNode, args, executor='events')


if __name__ == '__main__':
    raise SystemExit(main())
