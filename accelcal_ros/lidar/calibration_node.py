"""
Node ``lidar_calibration``: LiDAR-IMU boresight calibration on a live rig (paper B).

Subscribes ``points`` (sensor_msgs/PointCloud2, LiDAR frame) and ``imu/data_raw``
(sensor_msgs/Imu, specific force m/s^2, REP-145; gyro used when its covariance[0] != -1),
best effort (IMU depth ``imu_queue_depth``; scans depth ``queue_depth``, reliable with
``points_reliable``), deep enough that a process starved of CPU for seconds catches up on
its backlog without losing a position. Captures
a position automatically each time the rig rests (:mod:`accelcal_ros.lidar.capture`), or
on ``lidar_calibration/capture`` (std_srvs/Trigger). ``lidar_calibration/finish``
(Trigger) solves the boresight (:func:`accelcal_ros.lidar.boresight.calibrate_boresight`)
and writes ``output_file`` (YAML: ``R`` row-major LiDAR -> IMU, ``rpy_deg``,
``per_position_error_deg``, ``holdout_error_deg``, ...). Publishes nothing; the service
answers carry the result.
"""
import threading

from accelcal_ros.errors import AccelcalError
from accelcal_ros.lidar.params import capture_settings, LIDAR_CALIBRATION_PARAMS as SPECS
from accelcal_ros.rosutil.drops import DropCounter
from accelcal_ros.rosutil.params import ParameterSet
from accelcal_ros.rosutil.pointcloud2 import pointcloud2_to_array
from accelcal_ros.rosutil.runner import run
from accelcal_ros.rosutil.stamps import stamp_to_seconds
import numpy as np
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu, PointCloud2
from std_srvs.srv import Trigger


class LidarCalibrationNode(Node):
    """Thin wiring around :class:`~accelcal_ros.lidar.capture.StaticCapture`."""

    def __init__(self):
        super().__init__('lidar_calibration')
        self.params = ParameterSet(self, SPECS, self._on_change)
        from accelcal_ros.lidar.capture import CaptureSettings, StaticCapture

        model = None
        if self.params['calibration_file']:
            from accelcal_ros.sensor.calibration_file import load_sensor_model

            model = load_sensor_model(self.params['calibration_file'])
        self._lock = threading.Lock()
        self._settings = CaptureSettings()
        self._apply_settings()
        self._capture = StaticCapture(self._settings, model)
        self._was_still = False
        self._n_logged = 0
        self._warned = set()
        self._drops = DropCounter(self)
        imu_qos = QoSProfile(depth=self.params['imu_queue_depth'],
                             reliability=ReliabilityPolicy.BEST_EFFORT,
                             history=HistoryPolicy.KEEP_LAST)
        self.create_subscription(Imu, 'imu/data_raw', self._on_imu, imu_qos)
        reliability = (ReliabilityPolicy.RELIABLE if self.params['points_reliable']
                       else ReliabilityPolicy.BEST_EFFORT)
        points_qos = QoSProfile(depth=self.params['queue_depth'], reliability=reliability,
                                history=HistoryPolicy.KEEP_LAST)
        self.create_subscription(PointCloud2, 'points', self._on_cloud, points_qos)
        self.create_service(Trigger, 'lidar_calibration/capture', self._on_capture)
        self.create_service(Trigger, 'lidar_calibration/finish', self._on_finish)
        self.get_logger().info('waiting for the rig to rest (auto capture '
                               f'{"on" if self.params["auto_capture"] else "off"})')

    def _apply_settings(self, values=None):
        p = dict(self.params.values)
        p.update(values or {})
        capture_settings(p, self._settings)

    def _on_change(self, name, value):
        with self._lock:
            self._apply_settings({name: value})

    def _warn_once(self, key, text):
        if key not in self._warned:
            self._warned.add(key)
            self.get_logger().warning(text)

    def _on_imu(self, msg):
        a = msg.linear_acceleration
        accel = np.array([a.x, a.y, a.z])
        gyro = None
        if msg.angular_velocity_covariance[0] != -1.0:
            w = msg.angular_velocity
            gyro = np.array([w.x, w.y, w.z])
        if not (np.all(np.isfinite(accel)) and (gyro is None or np.all(np.isfinite(gyro)))):
            self._drops.drop('imu_samples', 'IMU sample with NaN ignored')
            return
        with self._lock:
            still = self._capture.add_imu(stamp_to_seconds(msg.header.stamp), accel, gyro)
            new = self._new_positions()
            backwards = self._capture.out_of_order
        if backwards:
            self._warn_once('imu_order', 'IMU stamps went backwards; such samples are ignored '
                            '(two publishers on imu/data_raw, or a clock jump?)')
        if still != self._was_still:
            self._was_still = still
            self.get_logger().info('rig at rest' if still else 'rig moving')
        for pos in new:
            self._log_capture(pos)

    def _on_cloud(self, msg):
        try:
            cloud = pointcloud2_to_array(msg)
            pts = np.stack([cloud['x'], cloud['y'], cloud['z']], axis=1).astype(float)
        except (AccelcalError, ValueError) as exc:
            self._drops.drop('clouds', f'unusable PointCloud2 ignored: {exc}')
            return
        with self._lock:
            self._capture.add_cloud(stamp_to_seconds(msg.header.stamp), pts)
            new = self._new_positions()
        for pos in new:
            self._log_capture(pos)

    def _new_positions(self):
        new = self._capture.positions[self._n_logged:]
        self._n_logged = len(self._capture.positions)
        return new

    def _log_capture(self, pos):
        g = pos.gravity_m_s2
        self.get_logger().info(f'captured {pos.name}: {len(pos.points)} points, gravity '
                               f'[{g[0]:.3f}, {g[1]:.3f}, {g[2]:.3f}] m/s^2 '
                               f'({len(self._capture.positions)} positions)')

    def _on_capture(self, request, response):
        with self._lock:
            pos, reason = self._capture.capture_now()
            self._new_positions()
        response.success = pos is not None
        response.message = reason if pos is None else (
            f'captured {pos.name} ({len(pos.points)} points)')
        if pos is not None:
            self._log_capture(pos)
        return response

    def _on_finish(self, request, response):
        from accelcal_ros.frames import rotation_from_rpy_radians
        from accelcal_ros.lidar.boresight import calibrate_boresight
        from accelcal_ros.lidar.calibrate_dir import report_lines, write_result
        from accelcal_ros.lidar.plane_fit import FloorSearch

        with self._lock:
            positions = list(self._capture.positions)
            p = dict(self.params.values)
        if len(positions) < p['min_positions']:
            response.success = False
            response.message = (f'only {len(positions)} positions captured, need '
                                f'{p["min_positions"]}: rest the rig in more orientations')
            return response
        prior = None
        if p['prior_rpy_deg']:
            prior = rotation_from_rpy_radians(*np.radians(p['prior_rpy_deg']))
        search = FloorSearch(distance_threshold_m=p['distance_threshold_m'],
                             max_tilt_deg=p['max_tilt_deg'], max_range_m=p['max_range_m'])
        try:
            result = calibrate_boresight(positions, prior, search, p['weighting'])
            write_result(p['output_file'], result)
        except (AccelcalError, OSError) as exc:
            response.success = False
            response.message = f'calibration failed: {exc}'
            self.get_logger().error(response.message)
            return response
        for line in report_lines(result):
            self.get_logger().info(line)
        r, pch, y = result.rpy_deg
        response.success = True
        response.message = (f'roll {r:.4f} pitch {pch:.4f} yaw {y:.4f} deg; mean error '
                            f'{result.mean_error_deg:.4f} deg over {len(result.positions)} '
                            f'positions; wrote {p["output_file"]}')
        return response


def main(args=None):
    """Run the ``lidar_calibration`` node."""
    return run(LidarCalibrationNode, args, executor='events')
