"""
``attitude``: calibrated roll and pitch from ``imu/data_raw`` (thin ROS wiring).

Subscribes ``imu/data_raw`` (sensor_msgs/Imu, m/s^2, sensor-data QoS). Publishes, with
the input's header (stamp and frame_id):

* ``attitude`` (geometry_msgs/Vector3Stamped): x = roll, y = pitch, z = 0, rad, REP-103;
* ``imu/data`` (sensor_msgs/Imu): calibrated linear acceleration (m/s^2), orientation
  with yaw 0 (``Ry(pitch) Rx(roll)``), orientation covariance from the noise and the
  calibration's uncertainty (roll, pitch; yaw variance ``yaw_variance``); angular
  velocity (bias removed) with its covariance when a gyro is used, else covariance[0] =
  -1 (not provided). While the sensor accelerates (| |f| - 1 g | above
  ``accel_threshold_g``) the last good tilt is held and its covariance inflated.

The estimate is :class:`~accelcal_ros.sensor.tilt_filter.AttitudeFilter`: averaging
adapted to stillness (``still_time_constant_s`` while still, ``moving_time_constant_s``
while moving), gyro-aided when angular velocity comes with the samples
(``angular_velocity_covariance[0] != -1`` in ``imu/data_raw``) or on ``gyro_topic`` (a
second sensor_msgs/Imu, the newest sample within 50 ms used; its frame must be the
accelerometer's unless ``gyro_rotation`` says how they relate), odometry-aided with
``odometry_topic`` (nav_msgs/Odometry; ``lever_arm_m``, which the gyro path uses too:
the rotation's acceleration at the sensor is removed and a turn leaves pitch to the
accelerometer). ``time_constant_s`` > 0 selects
the former fixed low-pass instead (accelerometer only). Bad gyro or odometry input is
not used, counted in ``/diagnostics`` and logged (throttled), with the reason; the
``attitude: tilt`` status's
``mode`` says what the tilt rests on (accelerometer only on a moving platform: WARN,
valid only while the platform does not accelerate).

The calibration comes from ``calibration_file`` or from the ``calibration.*`` parameters,
both settable at run time (``ros2 param set``, or the calibration node's finish). A bad
file or value is rejected with the reason and the last good calibration stays in use; at
start a bad file stops the node with the reason (it would otherwise run uncalibrated).
A ``calibration_file`` that does not exist yet (the node started before the calibration
was run) is a warning, given once: the node runs uncalibrated, checks every second and
loads the file when it appears (or uses a calibration pushed in the meantime).

Impossible input (NaN/infinite, a zero vector, a magnitude beyond any accelerometer such
as 1e300) publishes nothing: it is skipped, counted per reason in ``/diagnostics``
(``attitude: tilt``, once a second, with samples in and out) and logged at most every
10 s. Every dropped message goes through one
:class:`~accelcal_ros.rosutil.drops.DropCounter` (status ``attitude: dropped messages``;
kinds ``imu_nan``, ``imu_zero``, ``imu_out_of_range``, ``imu_unstamped``,
``imu_out_of_order``, ``imu_time_jump``, ``gyro_nan``, ``gyro_saturated``, ``gyro_frame``,
``odometry``; docs/attitude.md). Header stamps
(:class:`~accelcal_ros.rosutil.stamps.StampOrder`): a sample stamped 0 or not after the
previous one is skipped and counted; stamps jumping back by a second or more (a bag played
again) restart the estimate from that sample. Per sample the callback only assigns
plain floats into pre-built messages.
Core: :class:`~accelcal_ros.sensor.tilt.TiltEstimator`.
"""
import math
import os

from accelcal_ros.attitude.params import ATTITUDE_PARAMS
from accelcal_ros.errors import AccelcalError, InputError
from accelcal_ros.rosutil.drops import DropCounter
from accelcal_ros.rosutil.params import ParameterSet
from accelcal_ros.rosutil.qos import imu_subscription_qos
from accelcal_ros.rosutil.runner import run
from accelcal_ros.rosutil.stamps import JUMPED_BACK, StampOrder, TIME_JUMP_BACK_S, USE
from accelcal_ros.sensor.calibration_file import load_calibration
from accelcal_ros.sensor.datasheet import datasheet_noise_std_g
from accelcal_ros.sensor.model import SensorModel
from accelcal_ros.sensor.odometry_aid import OdometryAid
from accelcal_ros.sensor.tilt import quaternion_from_roll_pitch, TiltEstimator
from accelcal_ros.sensor.tilt_filter import AttitudeFilter, FilterSettings, MODE_BLIND
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Vector3Stamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Imu


DIAGNOSTICS_PERIOD_S = 1.0
"""Period of the /diagnostics status and of the check for a missing calibration file (s)."""
GYRO_MATCH_S = 0.05
"""A gyro sample from ``gyro_topic`` is used for accelerometer samples this close (s)."""
SKIP_KINDS = {'NaN': 'imu_nan', 'zero': 'imu_zero', 'out of range': 'imu_out_of_range'}
"""Drop kind of each reason :class:`TiltEstimator` gives for an impossible sample."""
FILTER_KEYS = ('still_time_constant_s', 'moving_time_constant_s', 'gyro_time_constant_s',
               'rejection_deg', 'rejection_timeout_s', 'bias_time_constant_s',
               'gyro_noise_std_rad_s', 'platform_accel_g')


class AttitudeNode(Node):
    """Thin node around :class:`TiltEstimator`."""

    def __init__(self):
        super().__init__('attitude')
        self.params = ParameterSet(self, ATTITUDE_PARAMS, on_change=self._on_change)
        values = self.params.values
        self.legacy = TiltEstimator(time_constant_s=values['time_constant_s'],
                                    accel_threshold_g=values['accel_threshold_g'],
                                    max_hold_s=values['max_hold_s'])
        self.filter = AttitudeFilter(accel_threshold_g=values['accel_threshold_g'],
                                     max_hold_s=values['max_hold_s'],
                                     settings=self._filter_settings(values),
                                     lever_arm_m=values['lever_arm_m'])
        self.estimator = self.legacy if values['time_constant_s'] > 0 else self.filter
        self._gyro_rotation = self._rotation(values['gyro_rotation'])
        self._gyro_sample = None
        self._gyro_frame_reason = ''
        self._odometry = None
        self._odometry_moving = None
        self._accel_frame = None
        self._gyro_seen = {'NaN': 0, 'saturated': 0}
        self._pending = {}
        self._rate_dt = None
        self._last_stamp = None
        self._stamp_order = StampOrder()
        self._noise_rate = None
        self._fixed_noise = bool(values['noise_std_g'])
        self._received = 0
        self._published = 0
        self.drops = DropCounter(self, DIAGNOSTICS_PERIOD_S)
        self._calibration_source = 'calibration.* parameters'
        self._waiting_for_file = ''
        self._set_calibration(*self._model_from_values(values))
        path = values['calibration_file']
        if path and not os.path.exists(os.path.expanduser(path)):
            self._waiting_for_file = path
            self._calibration_source = 'none yet (waiting for the calibration file)'
            self.get_logger().warning(
                f'calibration file {path} does not exist yet: running uncalibrated until '
                'it appears (checked every second) or a calibration is pushed')
        elif path:   # a bad file stops the node with the reason (the runner's FATAL line)
            self._load_file(path)
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
        if values['gyro_topic']:
            self.create_subscription(Imu, values['gyro_topic'], self._on_gyro,
                                     imu_subscription_qos())
        if values['odometry_topic']:
            self._odometry = OdometryAid(values['lever_arm_m'])
            self.create_subscription(Odometry, values['odometry_topic'], self._on_odometry,
                                     qos_profile_sensor_data)
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
        self._set_calibration(record.sensor_model, tilt_std_rad)
        self._waiting_for_file = ''
        self._calibration_source = f'file {path}'
        self.get_logger().info(
            f'loaded {record.model} calibration from {path}: scale '
            f'{record.sensor_model.scale.round(5).tolist()}, bias '
            f'{record.sensor_model.bias.round(5).tolist()} g')
        for note in record.notes:  # an uncertainty raised to the file's own known error
            self.get_logger().warning(f'{path}: {note}')

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
                self._set_calibration(*self._model_from_values(merged))
                self._calibration_source = 'calibration.* parameters'
        elif name.startswith('calibration.'):
            merged = dict(self.params.values)
            merged.update(self._pending)
            merged[name] = value
            sensor_model, tilt_std = self._model_from_values(merged)
            self._pending[name] = value
            self._set_calibration(sensor_model, tilt_std)
            self._waiting_for_file = ''
            self._calibration_source = 'calibration.* parameters'
        elif name == 'yaw_variance':
            self._out_imu.orientation_covariance[8] = float(value)
        elif name == 'time_constant_s':
            self.legacy.time_constant_s = value
            self.legacy.reset()
            self.filter.reset()
            self.estimator = self.legacy if value > 0 else self.filter
        elif name in ('accel_threshold_g', 'max_hold_s'):
            setattr(self.legacy, name, value)
            setattr(self.filter.tilt, name, value)
        elif name == 'noise_std_g':
            if value:
                self._set_noise(value)
            self._fixed_noise = bool(value)
            self._noise_rate = None
        elif name in FILTER_KEYS:
            merged = dict(self.params.values)
            merged[name] = value
            self.filter.set_settings(self._filter_settings(merged))
        elif name == 'gyro_rotation':
            self._gyro_rotation = self._rotation(value)
            self._gyro_frame_reason = ''
        elif name == 'lever_arm_m':
            self.filter.set_lever_arm(value)
            if self._odometry is not None:
                self._odometry.lever_arm_m = tuple(float(v) for v in value)

    # -- helpers ----------------------------------------------------------------------------
    @staticmethod
    def _filter_settings(values):
        try:
            return FilterSettings(**{k: float(values[k]) for k in FILTER_KEYS})
        except AccelcalError as exc:
            raise InputError(str(exc)) from None

    @staticmethod
    def _rotation(values):
        return [float(v) for v in values] if len(values) == 9 else None

    def _set_calibration(self, sensor_model, tilt_std_rad=None):
        self.legacy.set_calibration(sensor_model, tilt_std_rad)
        self.filter.set_calibration(sensor_model, tilt_std_rad)

    def _set_noise(self, noise):
        self.legacy.set_noise(noise)
        self.filter.set_noise(noise)

    def _problem(self, key, text):
        """Count a bad gyro/odometry input (kind ``key``); logged at most every 10 s."""
        self.drops.drop(key, text)

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
            self._set_noise(datasheet_noise_std_g(rate))

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
        self._accel_frame = header.frame_id
        stamp = header.stamp.sec + header.stamp.nanosec * 1e-9
        order = self._stamp_order.check(stamp)
        if order is not USE and not self._out_of_order(order):
            return
        self._update_noise(stamp)
        g = STANDARD_GRAVITY_M_S2
        estimator = self.estimator
        if estimator is self.legacy:
            est = estimator.update(stamp, (a.x / g, a.y / g, a.z / g))
            gyro = None
        else:
            gyro = self._gyro_for(msg, stamp)
            platform = moving = None
            odometry = self._odometry
            if odometry is not None:
                platform = odometry.accel_g(stamp)
                moving = self._odometry_moving if platform is not None else None
            est = estimator.update(stamp, (a.x / g, a.y / g, a.z / g), gyro, platform, moving)
        if est is None:
            self._skip(estimator.last_rejection)
            return
        if gyro is not None and estimator.gyro_rejections != self._gyro_seen:
            self._gyro_dropped(estimator.gyro_rejections)
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
        if gyro is not None and math.isfinite(gyro[0] + gyro[1] + gyro[2]):
            b = self.filter.gyro_bias_rad_s
            w = imu.angular_velocity
            w.x, w.y, w.z = gyro[0] - b[0], gyro[1] - b[1], gyro[2] - b[2]
            wcov = imu.angular_velocity_covariance
            wcov[0] = wcov[4] = wcov[8] = self.filter.settings.gyro_noise_std_rad_s ** 2
        elif imu.angular_velocity_covariance[0] != -1.0:
            imu.angular_velocity_covariance[0] = -1.0
            w = imu.angular_velocity
            w.x = w.y = w.z = 0.0
        source = self.legacy.force_covariance_list_g2
        if source is not self._fcov_source:   # changes with the calibration or the noise
            self._fcov_source = source
            imu.linear_acceleration_covariance = [v * g * g for v in source]
        self.imu_pub.publish(imu)
        self._published += 1

    def _gyro_for(self, msg, stamp):
        """Return the angular velocity (accelerometer frame, rad/s) for this sample or None."""
        if msg.angular_velocity_covariance[0] != -1.0:
            w = msg.angular_velocity
            return (w.x, w.y, w.z)
        sample = self._gyro_sample
        if sample is None or abs(sample[0] - stamp) > GYRO_MATCH_S:
            return None
        return sample[1]

    def _on_gyro(self, msg):
        """Keep the newest angular velocity of ``gyro_topic`` (a second Imu topic)."""
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        w = msg.angular_velocity
        rate = (w.x, w.y, w.z)
        rotation = self._gyro_rotation
        if rotation is not None:
            r = rotation
            rate = (r[0] * w.x + r[1] * w.y + r[2] * w.z, r[3] * w.x + r[4] * w.y + r[5] * w.z,
                    r[6] * w.x + r[7] * w.y + r[8] * w.z)
        elif self._accel_frame is not None and msg.header.frame_id != self._accel_frame:
            self._gyro_frame_reason = (
                f'gyro topic frame "{msg.header.frame_id}" differs from the accelerometer\'s '
                f'"{self._accel_frame}" and no gyro_rotation relates them: the gyro is not used')
            self._problem('gyro_frame', self._gyro_frame_reason)
            self._gyro_sample = None
            return
        self._gyro_sample = (stamp, rate)

    def _on_odometry(self, msg):
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        twist = msg.twist.twist
        last = self._odometry.last_t
        if last is not None and last - stamp >= TIME_JUMP_BACK_S:   # a bag played again
            self._odometry.reset()
        try:
            self._odometry.add(stamp, twist.linear.x, twist.angular.z)
        except AccelcalError as exc:
            self._problem('odometry', f'odometry: {exc}')
            return
        self._odometry_moving = abs(twist.linear.x) > 0.05 or abs(twist.angular.z) > 0.01

    def _gyro_dropped(self, rejections):
        """Count the gyro samples the filter did not use (NaN, saturated) since the last."""
        seen, self._gyro_seen = self._gyro_seen, dict(rejections)
        limit = self.filter.settings.gyro_saturation_rad_s
        for key, kind, why in (('NaN', 'gyro_nan', 'NaN'),
                               ('saturated', 'gyro_saturated', f'at the {limit} rad/s limit')):
            self.drops.drop(kind, f'gyro sample not used ({why}): a short gap is bridged with '
                            'the last good rate, a longer one falls back to the accelerometer',
                            rejections.get(key, 0) - seen.get(key, 0))

    def _out_of_order(self, order):
        """Count a stamp out of order; return True (use it) after a jump back, restarted."""
        self.drops.drop('imu_' + order, self._stamp_order.reason(
            order, 'imu/data_raw', 'the estimate restarts from this sample'))
        if order != JUMPED_BACK:
            return False
        self.filter.reset()
        self.legacy.reset()
        self._gyro_sample = None
        if self._odometry is not None:   # it refused every message until then
            self._odometry.reset()
        return True

    def _skip(self, reason):
        """Count an impossible sample and say so, at most every 10 s per reason."""
        self.drops.drop(SKIP_KINDS.get(reason, 'imu_out_of_range'),
                        f'imu/data_raw sample skipped ({reason}: a reading with no usable '
                        'direction)')

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
        drops = self.drops
        skipped = sum(drops.count(kind) for kind in SKIP_KINDS.values())
        problems = {k: drops.count(k) for k in ('gyro_frame', 'odometry') if drops.count(k)}
        if self._waiting_for_file:
            status.level = DiagnosticStatus.WARN
            status.message = (f'uncalibrated: waiting for {self._waiting_for_file}')
        elif not self.estimator.calibrated:
            status.level, status.message = DiagnosticStatus.WARN, 'uncalibrated'
        elif skipped:
            status.level = DiagnosticStatus.WARN
            status.message = f'{skipped} impossible samples skipped'
        elif drops.count('imu_unstamped') or drops.count('imu_out_of_order'):
            status.level = DiagnosticStatus.WARN
            status.message = (f'{drops.count("imu_unstamped") + drops.count("imu_out_of_order")}'
                              ' samples skipped: header stamp 0 or not after the previous')
        elif self._gyro_frame_reason:
            status.level, status.message = DiagnosticStatus.WARN, self._gyro_frame_reason
        elif problems:
            status.level = DiagnosticStatus.WARN
            status.message = 'bad gyro/odometry input: ' + ', '.join(
                f'{k} {v}' for k, v in sorted(problems.items()))
        elif self.estimator is self.filter and self.filter.mode == MODE_BLIND:
            status.level, status.message = DiagnosticStatus.WARN, MODE_BLIND
        else:
            status.level, status.message = DiagnosticStatus.OK, 'publishing'
        values = {'samples_received': str(self._received),
                  'samples_published': str(self._published),
                  'skipped_nan': str(drops.count('imu_nan')),
                  'skipped_zero': str(drops.count('imu_zero')),
                  'skipped_out_of_range': str(drops.count('imu_out_of_range')),
                  'skipped_stamp': str(drops.count('imu_unstamped')
                                       + drops.count('imu_out_of_order')),
                  'time_jumps_back': str(drops.count('imu_time_jump')),
                  'calibrated': str(self.estimator.calibrated).lower(),
                  'calibration_source': self._calibration_source,
                  'mode': 'fixed low-pass (time_constant_s), accelerometer only'
                  if self.estimator is self.legacy else self.filter.mode}
        if self.estimator is self.filter:
            f = self.filter
            values['still'] = str(f.detector.still).lower()
            values['gyro_bias_rad_s'] = ', '.join(f'{v:.5f}' for v in f.gyro_bias_rad_s)
            values['gyro_bias_known'] = str(f.bias_known).lower()
            values['accelerometer_rejected'] = str(f.rejecting).lower()
            values['gyro_nan'] = str(f.gyro_rejections['NaN'])
            values['gyro_saturated'] = str(f.gyro_rejections['saturated'])
        for key, count in problems.items():
            values[f'bad_{key}'] = str(count)
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
