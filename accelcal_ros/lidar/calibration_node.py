"""
Node ``lidar_calibration``: LiDAR-IMU boresight calibration on a live rig (paper B).

Subscribes ``points`` (sensor_msgs/PointCloud2, LiDAR frame) and ``imu/data_raw``
(sensor_msgs/Imu, specific force m/s^2, REP-145; gyro used when its covariance[0] != -1),
best effort (IMU depth ``imu_queue_depth``; scans depth ``queue_depth``, reliable with
``points_reliable``), deep enough that a process starved of CPU for seconds catches up on
its backlog without losing a position. The
calibration interface every calibration node shares (:mod:`accelcal_ros.session_interface`):
``lidar_calibration/start`` opens a session; it captures a position automatically each
time the rig rests (:mod:`accelcal_ros.lidar.capture`), or on
``lidar_calibration/capture``; ``lidar_calibration/finish`` solves the boresight
(:func:`accelcal_ros.lidar.boresight.calibrate_boresight`) and writes ``output_file``
(YAML: ``R`` row-major LiDAR -> IMU, ``rpy_deg``, ``per_position_error_deg``,
``holdout_error_deg``, ...); ``lidar_calibration/cancel`` drops the session. Publishes
``lidar_calibration/status`` (diagnostic_msgs/DiagnosticStatus, transient local) and
``/diagnostics``. The stillness settings take effect at the next start. After finish,
``imu_frame`` -> ``lidar_frame`` (the boresight and ``lever_arm_m``) is published on
``/tf_static`` as ``calibration_frames`` does.

Dropped input, counted in one :class:`~accelcal_ros.rosutil.drops.DropCounter`
(``lidar_calibration: dropped messages``) and logged at most every 10 s per kind:
``imu_samples`` (NaN/infinite), ``imu_samples_out_of_order`` (a stamp not after the
previous one), ``clouds`` (a PointCloud2 without x/y/z or with a bad layout) and
``clouds_overflow`` (scans waiting for the IMU stream beyond ``max_pending_scans``,
oldest first). Messages outside a session are not read (not a drop); a scan taken while
the rig moves is not used by design (not a drop either).
"""
import os
import threading

from accelcal_ros.errors import AccelcalError, CalibrationError
from accelcal_ros.lidar.capture import CaptureSettings, StaticCapture
from accelcal_ros.lidar.params import capture_settings, LIDAR_CALIBRATION_PARAMS as SPECS
from accelcal_ros.rosutil.calibration_interface import CalibrationInterface
from accelcal_ros.rosutil.drops import DropCounter
from accelcal_ros.rosutil.params import ParameterSet
from accelcal_ros.rosutil.pointcloud2 import pointcloud2_to_array
from accelcal_ros.rosutil.runner import run
from accelcal_ros.rosutil.stamps import stamp_to_seconds
from accelcal_ros.rosutil.static_tf import StaticBroadcaster
from accelcal_ros.session_interface import no_samples_reason, OK, SessionProgress, WARN
import numpy as np
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu, PointCloud2


class LidarCalibrationNode(Node):
    """Thin wiring around :class:`~accelcal_ros.lidar.capture.StaticCapture`."""

    def __init__(self):
        super().__init__('lidar_calibration')
        self.params = ParameterSet(self, SPECS, self._on_change)
        self._model = None
        if self.params['calibration_file']:
            from accelcal_ros.sensor.calibration_file import load_sensor_model

            self._model = load_sensor_model(self.params['calibration_file'])
        self._lock = threading.Lock()
        self._settings = CaptureSettings()
        self._apply_settings()
        self._capture = None
        self._last = None
        self._was_still = False
        self._n_logged = 0
        self._warned = set()
        self._drops = DropCounter(self)
        imu_qos = QoSProfile(depth=self.params['imu_queue_depth'],
                             reliability=ReliabilityPolicy.BEST_EFFORT,
                             history=HistoryPolicy.KEEP_LAST)
        self._session_samples = 0
        self._imu_sub = self.create_subscription(Imu, 'imu/data_raw', self._on_imu, imu_qos)
        reliability = (ReliabilityPolicy.RELIABLE if self.params['points_reliable']
                       else ReliabilityPolicy.BEST_EFFORT)
        points_qos = QoSProfile(depth=self.params['queue_depth'], reliability=reliability,
                                history=HistoryPolicy.KEEP_LAST)
        self.create_subscription(PointCloud2, 'points', self._on_cloud, points_qos)
        self.session = CalibrationInterface(
            self, self, 'LiDAR-IMU boresight calibration', 'lidar+imu',
            'rest the rig with the floor in view (auto capture) or call '
            'lidar_calibration/capture while it rests', self.params['status_period_s'])
        self.get_logger().info('ready: call lidar_calibration/start, rest the rig in '
                               f'{self.params["min_positions"]} or more tilts (auto capture '
                               f'{"on" if self.params["auto_capture"] else "off"}), then call '
                               'lidar_calibration/finish')
        self._tf = StaticBroadcaster(self)

    def _apply_settings(self, values=None):
        p = dict(self.params.values)
        p.update(values or {})
        capture_settings(p, self._settings)

    def _on_change(self, name, value):
        with self._lock:
            self._apply_settings({name: value})
        if name == 'status_period_s':
            self.session.set_period(value)

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
            if self._capture is None:
                return
            before = self._capture.out_of_order
            still = self._capture.add_imu(stamp_to_seconds(msg.header.stamp), accel, gyro)
            new = self._new_positions()
            backwards = self._capture.out_of_order - before
            self._session_samples += not backwards
        if backwards:
            self._drops.drop('imu_samples_out_of_order', 'IMU stamp not after the previous '
                             'one: sample ignored (two publishers on imu/data_raw, or a clock '
                             'jump?)', backwards)
        if still != self._was_still:
            self._was_still = still
            self.get_logger().info('rig at rest' if still else 'rig moving')
        for pos in new:
            self._log_capture(pos)

    def _on_cloud(self, msg):
        if self._capture is None:
            return
        try:
            cloud = pointcloud2_to_array(msg)
            pts = np.stack([cloud['x'], cloud['y'], cloud['z']], axis=1).astype(float)
        except (AccelcalError, ValueError) as exc:
            self._drops.drop('clouds', f'unusable PointCloud2 ignored: {exc}')
            return
        with self._lock:
            if self._capture is None:
                return
            before = self._capture.scans_overflowed
            self._capture.add_cloud(stamp_to_seconds(msg.header.stamp), pts)
            new = self._new_positions()
            overflowed = self._capture.scans_overflowed - before
        if overflowed:
            self._drops.drop('clouds_overflow', 'scans waiting for the IMU stream beyond '
                             'max_pending_scans: the oldest dropped (is imu/data_raw '
                             'arriving?)', overflowed)
        for pos in new:
            self._log_capture(pos)

    def _new_positions(self):
        new = self._capture.positions[self._n_logged:]
        self._n_logged = len(self._capture.positions)
        return new

    def _captured_text(self, pos):
        g = pos.gravity_m_s2
        return (f'captured {pos.name}: {len(pos.points)} points, gravity '
                f'[{g[0]:.3f}, {g[1]:.3f}, {g[2]:.3f}] m/s^2 '
                f'({self._n_logged} positions)')

    def _log_capture(self, pos):
        self.session.event(self._captured_text(pos))

    # -- the session (backend of CalibrationInterface) -------------------------------------
    def begin(self):
        """Open a session: a fresh capture with the current settings."""
        with self._lock:
            self._apply_settings()
            self._capture = StaticCapture(self._settings, self._model)
            self._session_samples = 0
            self._n_logged = 0
            self._was_still = False
        return ('boresight calibration started: rest the rig in '
                f'{self.params["min_positions"]} or more tilts with the floor in view (auto '
                f'capture {"on" if self.params["auto_capture"] else "off"})')

    def capture(self):
        """Capture the current still period (CalibrationError with the reason)."""
        with self._lock:
            if not self._session_samples:
                raise CalibrationError(no_samples_reason(self._imu_sub.topic_name,
                                                         self._capture.out_of_order))
            pos, reason = self._capture.capture_now()
            self._new_positions()
        if pos is None:
            raise CalibrationError(reason)
        return self._captured_text(pos)

    def discard(self):
        """Drop the session."""
        with self._lock:
            capture, self._capture = self._capture, None
        return len(capture.positions)

    def output_file(self):
        """Return the boresight file finish writes (~ expanded)."""
        return os.path.expanduser(self.params['output_file'])

    def solve(self):
        """Solve the boresight from the session's positions and write output_file."""
        from accelcal_ros.frame_tree import lidar_transform, names_from_values
        from accelcal_ros.frames import rotation_from_rpy_radians
        from accelcal_ros.lidar.boresight import calibrate_boresight
        from accelcal_ros.lidar.calibrate_dir import report_lines, write_result
        from accelcal_ros.lidar.plane_fit import FloorSearch

        with self._lock:
            positions = list(self._capture.positions)
            p = dict(self.params.values)
        if len(positions) < p['min_positions']:
            raise CalibrationError(f'only {len(positions)} positions captured, need '
                                   f'{p["min_positions"]}: rest the rig in more orientations')
        prior = None
        if p['prior_rpy_deg']:
            prior = rotation_from_rpy_radians(*np.radians(p['prior_rpy_deg']))
        search = FloorSearch(distance_threshold_m=p['distance_threshold_m'],
                             max_tilt_deg=p['max_tilt_deg'], max_range_m=p['max_range_m'])
        path = self.output_file()
        result = calibrate_boresight(positions, prior, search, p['weighting'])
        write_result(path, result)
        self._tf.send([lidar_transform(names_from_values(p), result.rotation,
                                       p['lever_arm_m'])])
        for line in report_lines(result):
            self.get_logger().info(line)
        with self._lock:
            self._last, self._capture = result, None
        r, pch, y = result.rpy_deg
        return (f'roll {r:.4f} pitch {pch:.4f} yaw {y:.4f} deg; mean error '
                f'{result.mean_error_deg:.4f} deg over {len(result.positions)} '
                f'positions; wrote {path}')

    def progress(self, active):
        """Return the :class:`SessionProgress` of the session, or of the last result."""
        needed = self.params['min_positions']
        with self._lock:
            capture = self._capture
            count = len(capture.positions) if capture is not None else 0
            still = capture.still if capture is not None else False
        if capture is None:
            r = self._last
            if r is None:
                return SessionProgress(0, needed)
            roll, pitch, yaw = r.rpy_deg
            return SessionProgress(
                len(r.positions), needed, None, 1.96 * float(np.max(r.rpy_std_deg)),
                'call lidar_calibration/start for a new calibration',
                {'rpy_deg': f'{roll:.4f} {pitch:.4f} {yaw:.4f}',
                 'mean_error_deg': f'{r.mean_error_deg:.4f}',
                 'warnings': '; '.join(r.warnings)},
                f'last calibration: roll {roll:.4f} pitch {pitch:.4f} yaw {yaw:.4f} deg',
                WARN if r.warnings else OK)
        hint = (f'rest the rig in {needed - count} more tilts with the floor in view'
                if count < needed else 'enough positions: call lidar_calibration/finish '
                '(more tilts lower the error)')
        return SessionProgress(count, needed, None, None, hint,
                               {'still': str(still).lower()})


def main(args=None):
    """Run the ``lidar_calibration`` node."""
    return run(LidarCalibrationNode, args, executor='events')
