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
Core: :class:`~accelcal_ros.sensor.tilt.TiltEstimator`.
"""
import math
import os

from accelcal_ros.attitude.params import ATTITUDE_PARAMS
from accelcal_ros.errors import AccelcalError, InputError
from accelcal_ros.rosutil.params import ParameterSet
from accelcal_ros.rosutil.runner import run
from accelcal_ros.rosutil.stamps import stamp_to_seconds
from accelcal_ros.sensor.calibration_file import load_calibration
from accelcal_ros.sensor.datasheet import datasheet_noise_std_g
from accelcal_ros.sensor.model import SensorModel
from accelcal_ros.sensor.tilt import quaternion_from_roll_pitch, TiltEstimator
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
from geometry_msgs.msg import Vector3Stamped
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Imu


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
        self._warned_nan = False
        self._rate_dt = None
        self._last_stamp = None
        self._noise_rate = None
        self.estimator.set_calibration(*self._model_from_values(values))
        if values['calibration_file']:
            try:
                self._load_file(values['calibration_file'])
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
        self.create_subscription(Imu, 'imu/data_raw', self._on_imu, qos_profile_sensor_data)
        self._out_att = Vector3Stamped()
        self._out_imu = Imu()
        self._out_imu.angular_velocity_covariance[0] = -1.0

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
        elif name.startswith('calibration.'):
            merged = dict(self.params.values)
            merged.update(self._pending)
            merged[name] = value
            sensor_model, tilt_std = self._model_from_values(merged)
            self._pending[name] = value
            self.estimator.set_calibration(sensor_model, tilt_std)
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
            self._noise_rate = None

    # -- samples ----------------------------------------------------------------------------
    def _update_noise(self, stamp):
        """Follow the measured sample rate with the datasheet noise (noise_std_g empty)."""
        if self._last_stamp is not None and stamp > self._last_stamp:
            dt = stamp - self._last_stamp
            self._rate_dt = dt if self._rate_dt is None else 0.99 * self._rate_dt + 0.01 * dt
        self._last_stamp = stamp
        if self.params['noise_std_g'] or self._rate_dt is None:
            return
        rate = 1.0 / self._rate_dt
        if self._noise_rate is None or abs(rate - self._noise_rate) > 0.1 * self._noise_rate:
            self._noise_rate = rate
            self.estimator.set_noise(datasheet_noise_std_g(rate))

    def _on_imu(self, msg):
        if self._pending:
            self._pending.clear()
            v = self.params.values
            self.get_logger().info(
                f'calibration set: {v["calibration.model"]}, scale '
                f'{[round(x, 5) for x in v["calibration.scale"]]}, bias '
                f'{[round(x, 5) for x in v["calibration.bias"]]} g, misalignment '
                f'{[round(x, 6) for x in v["calibration.misalignment"]]} rad')
        a = msg.linear_acceleration
        stamp = stamp_to_seconds(msg.header.stamp)
        self._update_noise(stamp)
        g = STANDARD_GRAVITY_M_S2
        est = self.estimator.update(stamp, (a.x / g, a.y / g, a.z / g))
        if est is None:
            if not self._warned_nan:
                self._warned_nan = True
                self.get_logger().warning('imu/data_raw has NaN or infinite samples; they are '
                                          'skipped (reported once)')
            return
        att = self._out_att
        att.header = msg.header
        att.vector.x, att.vector.y, att.vector.z = est.roll, est.pitch, 0.0
        self.attitude_pub.publish(att)
        imu = self._out_imu
        imu.header = msg.header
        q = quaternion_from_roll_pitch(est.roll, est.pitch)
        imu.orientation.x, imu.orientation.y, imu.orientation.z, imu.orientation.w = q
        cov = est.covariance
        imu.orientation_covariance = [float(cov[0, 0]), float(cov[0, 1]), 0.0,
                                      float(cov[1, 0]), float(cov[1, 1]), 0.0,
                                      0.0, 0.0, float(self.params['yaw_variance'])]
        f = est.force_g * STANDARD_GRAVITY_M_S2
        imu.linear_acceleration.x, imu.linear_acceleration.y, imu.linear_acceleration.z = (
            float(f[0]), float(f[1]), float(f[2]))
        fcov = self.estimator.force_covariance_g2() * STANDARD_GRAVITY_M_S2 ** 2
        imu.linear_acceleration_covariance = [float(v) for v in fcov.ravel()]
        self.imu_pub.publish(imu)


def main(args=None):
    """Run the ``attitude`` node."""
    return run(AttitudeNode, args, executor='events')


if __name__ == '__main__':
    raise SystemExit(main())
