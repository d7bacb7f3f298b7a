"""
``imu_driver``: publishes ADXL345 samples as sensor_msgs/Imu (REP-145), thin ROS wiring.

Topics (relative): ``imu/data_raw`` (sensor_msgs/Imu, m/s^2, +9.8 on the up axis at rest,
orientation and angular velocity covariance element 0 = -1: not provided; linear
acceleration covariance from the datasheet noise model; sensor-data QoS),
``sim/attitude_truth`` (geometry_msgs/Vector3Stamped, x = roll, y = pitch in rad, sim
backend only, same stamps) and ``/diagnostics`` (achieved rate, bus errors, FIFO
overruns and the samples they lost, and with FIFO reads the sensor's measured output data
rate, to which the stamps are disciplined). Service ``~/self_test`` (std_srvs/Trigger):
the ADXL345's self-test, pass/fail per axis with the measured change. Samples are
published from a dedicated thread paced by the source, so the executor's timers do not
limit the rate. Parameters: :data:`~accelcal_ros.driver.params.
DRIVER_PARAMS`.
"""
import threading
import time

from accelcal_ros.driver.gyro_source import make_gyro
from accelcal_ros.driver.params import DRIVER_PARAMS, make_source
from accelcal_ros.errors import AccelcalError
from accelcal_ros.rosutil.diagnostics import PeriodicTimer
from accelcal_ros.rosutil.params import ParameterSet
from accelcal_ros.rosutil.runner import run
from accelcal_ros.sensor.datasheet import datasheet_noise_std_g
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Vector3Stamped
import numpy as np
import rclpy
from rclpy._rclpy_pybind11 import InvalidHandle, RCLError
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Imu
from std_srvs.srv import Trigger


class ImuDriverNode(Node):
    """Thin node around a sample source (sim, I2C or replay)."""

    def __init__(self):
        super().__init__('imu_driver')
        self.params = ParameterSet(self, DRIVER_PARAMS, self._on_change)
        self.source = make_source(self.params.values)
        self.source.start()
        if getattr(self.source, 'rate_warning', ''):
            self.get_logger().warning(self.source.rate_warning + ' (running anyway: '
                                      'allow_unsustainable_rate is true)')
        self.gyro = make_gyro(self.params.values, self.source)   # None: no gyro
        backend = self.params['backend']
        self.imu_pub = self.create_publisher(Imu, 'imu/data_raw', qos_profile_sensor_data)
        self.truth_pub = (self.create_publisher(Vector3Stamped, 'sim/attitude_truth',
                                                qos_profile_sensor_data)
                          if backend == 'sim' and self.params['sim.bus'] == 'none' else None)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._imu = Imu()
        std = datasheet_noise_std_g(self.params['rate_hz']) * STANDARD_GRAVITY_M_S2
        if backend == 'sim':
            std = std * self.params['sim.noise_scale']
        self._imu.linear_acceleration_covariance = [float(std[0] ** 2), 0.0, 0.0,
                                                    0.0, float(std[1] ** 2), 0.0,
                                                    0.0, 0.0, float(std[2] ** 2)]
        self._imu.orientation_covariance[0] = -1.0
        self._imu.angular_velocity_covariance[0] = -1.0
        self._truth = Vector3Stamped()
        self._published = 0
        self._diag_last = (time.monotonic(), 0)
        self._finished_logged = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._publish_loop, daemon=True)
        self._thread.start()
        self._diag_timer = PeriodicTimer(self, self.params['diagnostics_period_s'],
                                         self._publish_diagnostics)
        self.create_service(Trigger, '~/self_test', self._self_test)
        self.get_logger().info(
            f'publishing {backend} ADXL345 at {self.params["rate_hz"]:g} Hz on '
            f'{self.imu_pub.topic_name} (frame {self.params["frame_id"]})')

    def _on_change(self, name, value):
        if name == 'diagnostics_period_s':
            self._diag_timer.set_period(value)

    def _publish_loop(self):
        source = self.source
        while not self._stop.is_set():
            wait = source.next_poll_time() - time.time()
            if wait > 0 and self._stop.wait(wait):
                break
            batch = source.poll()
            if len(batch):
                try:
                    self._publish(batch)
                except (RCLError, InvalidHandle):
                    if self._stop.is_set() or not rclpy.ok():
                        break   # shutting down (Ctrl-C): the publisher went away
                    raise

    def _publish(self, batch):
        # Per sample only plain-float assignments into pre-built messages (no numpy
        # indexing, no new message objects).
        imu, truth = self._imu, self._truth
        imu.header.frame_id = truth.header.frame_id = self.params['frame_id']
        stamp, a = imu.header.stamp, imu.linear_acceleration
        rates = None
        if self.gyro is not None:   # one stamped ITG-3205 read per poll, interpolated
            cov = imu.angular_velocity_covariance
            if self.gyro.read_stamped() is None:
                cov[0] = -1.0
            else:
                rates = self.gyro.rates_at(batch.stamps.tolist())
                cov[0] = cov[4] = cov[8] = self.gyro.variance
        w = imu.angular_velocity
        publish = self.imu_pub.publish
        accel = (batch.samples_g * STANDARD_GRAVITY_M_S2).tolist()
        stamps_ns = (batch.stamps * 1e9).astype(np.int64).tolist()
        with_truth = self.truth_pub is not None and batch.truth_rp is not None
        truth_rp = batch.truth_rp.tolist() if with_truth else None
        for k, total_ns in enumerate(stamps_ns):
            stamp.sec, stamp.nanosec = divmod(total_ns, 1_000_000_000)
            a.x, a.y, a.z = accel[k]
            if rates is not None:
                w.x, w.y, w.z = rates[k]
            publish(imu)
            if with_truth:
                truth.header.stamp = stamp
                truth.vector.x, truth.vector.y = truth_rp[k]
                self.truth_pub.publish(truth)
        self._published += len(stamps_ns)

    def _publish_diagnostics(self):
        now, count = time.monotonic(), self._published
        last_time, last_count = self._diag_last
        self._diag_last = (now, count)
        achieved = (count - last_count) / max(now - last_time, 1e-9)
        stats = self.source.stats
        nominal = self.params['rate_hz']
        status = DiagnosticStatus(name=f'{self.get_name()}: ADXL345 ({self.params["backend"]})',
                                  hardware_id=self._hardware_id())
        bus = getattr(self.source, 'bus', 'I2C').upper()
        if stats.consecutive_errors >= 10:
            status.level, status.message = DiagnosticStatus.ERROR, \
                f'{bus} failing: {stats.last_error}; retrying with back-off'
        elif getattr(self.source, 'rate_warning', ''):
            status.level, status.message = DiagnosticStatus.WARN, \
                f'unsustainable rate, achieved {achieved:.1f} Hz: {self.source.rate_warning}'
        elif stats.finished:
            status.level, status.message = DiagnosticStatus.OK, 'replay finished'
        elif achieved < 0.9 * nominal:
            status.level, status.message = DiagnosticStatus.WARN, \
                f'rate {achieved:.1f} Hz below nominal {nominal:g} Hz'
        else:
            status.level, status.message = DiagnosticStatus.OK, 'publishing'
        values = {'rate_hz_nominal': f'{nominal:g}', 'rate_hz_achieved': f'{achieved:.2f}',
                  'samples_published': str(count), 'i2c_errors': str(stats.io_errors),
                  'fifo_overruns': str(stats.fifo_overruns), 'last_error': stats.last_error}
        if hasattr(self.source, 'diagnostic_values'):   # the ADXL345: bus, lost samples
            values.update(self.source.diagnostic_values())
        if stats.measured_rate_hz == stats.measured_rate_hz:   # not NaN: FIFO reads
            values['output_data_rate_hz_measured'] = f'{stats.measured_rate_hz:.2f}'
            values['fifo_stamp_resyncs'] = str(stats.stamp_resyncs)
        if self.gyro is not None:
            values.update({'gyro': 'itg3205', 'gyro_rate_hz': f'{self.gyro.rate_hz:g}',
                           'gyro_errors': str(self.gyro.errors),
                           'gyro_saturated': str(self.gyro.saturated)})
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)
        if stats.finished and not self._finished_logged:
            self._finished_logged = True
            self.get_logger().info(f'replay finished after {count} samples')

    def _self_test(self, request, response):
        """``~/self_test`` (std_srvs/Trigger): the ADXL345's self-test, pass/fail per axis."""
        if not hasattr(self.source, 'self_test'):
            response.success = False
            response.message = ('self-test needs the ADXL345 registers: backend i2c or spi, '
                                f'or sim with sim.bus i2c|spi (this is {self.params["backend"]})')
            return response
        try:
            result = self.source.self_test(self.params['supply_voltage_v'])
        except (AccelcalError, OSError) as exc:
            response.success, response.message = False, f'self-test not run: {exc}'
            return response
        response.success, response.message = result.passed, result.summary()
        self.get_logger().info(result.summary())
        return response

    def _hardware_id(self):
        if self.params['backend'] == 'i2c':
            return f'adxl345@i2c-{self.params["i2c_bus"]}:0x{self.params["i2c_address"]:02x}'
        if self.params['backend'] == 'spi':
            return f'adxl345@spi{self.params["spi_bus"]}.{self.params["spi_device"]}'
        return f'adxl345-{self.params["backend"]}'

    def close(self):
        """Stop the publishing thread."""
        self._stop.set()
        self._thread.join(timeout=2.0)


def main(args=None):
    """Run the ``imu_driver`` node."""
    return run(ImuDriverNode, args, executor='events')


if __name__ == '__main__':
    raise SystemExit(main())
