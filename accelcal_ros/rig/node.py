"""
Node ``rig_calibration``: calibrate a camera rig and its IMU mounting live (issue 12).

Like camera_calibration: subscribes ``<camera>/image_raw`` (sensor_msgs/Image) for each
name in ``cameras`` and ``imu/data_raw`` (sensor_msgs/Imu, m/s^2, REP-145), both best
effort. The calibration interface every calibration node shares
(:mod:`accelcal_ros.session_interface`): ``rig_calibration/start`` opens a session (poses
go to ``capture_dir/session_<UTC time>/``); a pose is captured automatically each time
the rig rests for ``min_still_s`` with the board in view
(:class:`accelcal_ros.rig.capture.RigCapture`), or on ``rig_calibration/capture``;
``rig_calibration/finish`` calibrates the session's poses and writes ``output_file`` (the
stitcher's rig file with ``imu_to_camera``), its report and plot;
``rig_calibration/cancel`` drops the session. ``rig_calibration/status``
(diagnostic_msgs/DiagnosticStatus, transient local) and ``/diagnostics`` say per camera
how many views and how much of the image they cover (``<camera>.views``,
``<camera>.coverage_percent``), per pair how many shared views
(``shared_views.<a>-<b>``), and what to do next (``hint``).
After finish, ``imu_frame`` -> the reference camera's optical frame -> every other
camera's is published on ``/tf_static`` (from the rig file written, as
``calibration_frames`` reads it).
"""
import os
import threading
import time

from accelcal_ros.errors import AccelcalError, CalibrationError, FileWriteError, InputError
from accelcal_ros.rig.calibrate import MIN_VIEWS_PER_CAMERA
from accelcal_ros.rig.params import reference_problem, RIG_CALIBRATION_PARAMS as SPECS
from accelcal_ros.rosutil.calibration_interface import CalibrationInterface
from accelcal_ros.rosutil.drops import DropCounter
from accelcal_ros.rosutil.images import image_msg_to_array
from accelcal_ros.rosutil.params import ParameterSet
from accelcal_ros.rosutil.runner import run
from accelcal_ros.rosutil.stamps import JUMPED_BACK, stamp_to_seconds, StampOrder, USE
from accelcal_ros.rosutil.static_tf import StaticBroadcaster
from accelcal_ros.session_interface import no_samples_reason, OK, SessionProgress, WARN
import numpy as np
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image, Imu


class RigCalibrationNode(Node):
    """Thin wiring around :class:`~accelcal_ros.rig.capture.RigCapture`."""

    def __init__(self):
        super().__init__('rig_calibration')
        self.params = ParameterSet(self, SPECS, self._on_change)
        p = self.params
        problem = reference_problem(p['reference'], list(p['cameras']))
        if problem:
            raise InputError(f'invalid parameter value(s): {problem} (given at start-up)')
        from accelcal_ros.rig.board import Board, parse_board_size

        self._model = None
        if p['calibration_file']:
            from accelcal_ros.sensor.calibration_file import load_sensor_model

            self._model = load_sensor_model(p['calibration_file'])
        self._board = Board(*parse_board_size(p['board']), p['square_m'])
        self._lock = threading.Lock()
        self._capture = None
        self._last = None
        self._warned = set()
        sensor_qos = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT,
                                history=HistoryPolicy.KEEP_LAST)
        imu_qos = QoSProfile(depth=2000, reliability=ReliabilityPolicy.BEST_EFFORT,
                             history=HistoryPolicy.KEEP_LAST)
        for name in p['cameras']:
            self.create_subscription(Image, f'{name}/image_raw',
                                     lambda msg, cam=name: self._on_image(cam, msg), sensor_qos)
        self._session_samples = 0
        self._stamp_order = StampOrder()
        self._skips_at_start = 0
        self._imu_sub = self.create_subscription(Imu, 'imu/data_raw', self._on_imu, imu_qos)
        self.session = CalibrationInterface(
            self, self, 'camera rig calibration', 'rig ' + ' '.join(p['cameras']),
            f'show the {p["board"]} board to the cameras and rest the rig (auto capture) '
            'or call rig_calibration/capture while it rests', p['status_period_s'])
        self.get_logger().info(f'ready: cameras {", ".join(p["cameras"])}, board '
                               f'{p["board"]}; call rig_calibration/start, rest the rig with '
                               'the board in view in a dozen poses, then call '
                               'rig_calibration/finish')
        self._tf = StaticBroadcaster(self)
        self._drops = DropCounter(self)

    def _on_change(self, name, value):
        if name == 'reference':
            problem = reference_problem(value, list(self.params['cameras']))
            if problem:
                raise InputError(problem)
        with self._lock:
            if name == 'auto_capture' and self._capture is not None:
                self._capture.auto = bool(value)
            elif name == 'min_still_s' and self._capture is not None:
                self._capture.min_still_s = float(value)
        if name == 'status_period_s':
            self.session.set_period(value)

    def _warn_once(self, key, text):
        if key not in self._warned:
            self._warned.add(key)
            self.get_logger().warning(text)

    def _on_image(self, camera, msg):
        if self._capture is None:
            return
        try:
            grey = image_msg_to_array(msg, want='mono8', topic=f'{camera}/image_raw')
        except AccelcalError as exc:
            self._drops.drop(f'{camera}_images', f'unusable image ignored: {exc}')
            return
        with self._lock:
            if self._capture is not None:
                self._capture.add_image(camera, stamp_to_seconds(msg.header.stamp), grey)

    def _on_imu(self, msg):
        a = msg.linear_acceleration
        accel = np.array([a.x, a.y, a.z])
        if not np.all(np.isfinite(accel)):
            self._drops.drop('imu_samples', 'IMU sample with NaN ignored')
            return
        t = stamp_to_seconds(msg.header.stamp)
        with self._lock:
            if self._capture is None:
                return
            order = self._stamp_order.check(t)
            name = None
            if order == JUMPED_BACK:
                self._capture.restart_clock()
            if order is USE or order == JUMPED_BACK:
                name = self._capture.add_imu(t, accel)
                self._session_samples += 1
            count = len(self._capture.poses)
        if order is not USE:
            self._drops.drop('imu_' + order, self._stamp_order.reason(
                order, 'imu/data_raw', 'the current still pose ends there'))
        if name:
            self.session.event(f'captured {name} ({count} poses)')

    # -- the session (backend of CalibrationInterface) -------------------------------------
    def begin(self):
        """Open a session: a fresh capture folder session_<UTC time> in capture_dir."""
        from accelcal_ros.rig.capture import RigCapture

        p = self.params
        stamp = time.strftime('%Y%m%dT%H%M%S', time.gmtime())
        folder = os.path.join(os.path.expanduser(p['capture_dir']), f'session_{stamp}')
        suffix = 1
        while os.path.exists(folder):
            suffix += 1
            folder = os.path.join(os.path.expanduser(p['capture_dir']),
                                  f'session_{stamp}_{suffix}')
        try:
            capture = RigCapture(folder, list(p['cameras']), self._board, p['auto_capture'],
                                 p['min_still_s'])
        except OSError as exc:
            raise FileWriteError(f'cannot create {folder}: {exc}; set capture_dir to a '
                                 'writable directory') from exc
        with self._lock:
            self._capture = capture
            self._session_samples = 0
            self._skips_at_start = self._stamp_order.skipped
        return (f'rig calibration started: poses go to {folder}; rest the rig with the '
                f'{p["board"]} board in view (auto capture '
                f'{"on" if p["auto_capture"] else "off"})')

    def capture(self):
        """Capture the current still pose (CalibrationError with the reason)."""
        with self._lock:
            if not self._session_samples:
                raise CalibrationError(no_samples_reason(
                    self._imu_sub.topic_name, self._stamp_order.skipped - self._skips_at_start))
            ok, message = self._capture.capture()
        if not ok:
            raise CalibrationError(message)
        return message

    def discard(self):
        """Drop the session (its images stay in the session folder)."""
        with self._lock:
            capture, self._capture = self._capture, None
        return len(capture.poses)

    def output_file(self):
        """Return the rig file finish writes (~ expanded)."""
        return os.path.expanduser(self.params['output_file'])

    def solve(self):
        """Calibrate the session's poses, write the rig file, report and plot."""
        from accelcal_ros.camera.rig import load_rig
        from accelcal_ros.frame_tree import camera_transforms, names_from_values
        from accelcal_ros.rig.report import report_lines, write_outputs

        p = dict(self.params.values)
        with self._lock:
            result = self._capture.finish(p['reference'] or None, self._model)
        paths = write_outputs(self.output_file(), result)
        self._tf.send(camera_transforms(names_from_values(p), load_rig(paths[0])))
        for line in report_lines(result):
            self.get_logger().info(line)
        with self._lock:
            self._last, self._capture = (result, len(self._capture.poses)), None
        return (f'{len(result.cameras)} cameras, rig fit RMS {result.fit.rms_px:.3f} px, '
                f'{len(result.warnings)} warnings; wrote {", ".join(paths)}')

    def progress(self, active):
        """Return the :class:`SessionProgress` of the session, or of the last result."""
        with self._lock:
            capture = self._capture
            status = capture.status() if capture is not None else None
        if status is None:
            if self._last is None:
                return SessionProgress(0, MIN_VIEWS_PER_CAMERA)
            result, poses = self._last
            std = float(np.max(result.fit.rotation_std_deg))
            return SessionProgress(
                poses, MIN_VIEWS_PER_CAMERA, None, 1.96 * std,
                'call rig_calibration/start for a new calibration',
                {'fit_rms_px': f'{result.fit.rms_px:.3f}',
                 'warnings': '; '.join(result.warnings)},
                f'last calibration: {len(result.cameras)} cameras, rig fit RMS '
                f'{result.fit.rms_px:.3f} px', WARN if result.warnings else OK)
        cams = status['cameras']
        extra = {'still': str(status['still']).lower(), 'capture_dir': capture.directory}
        for cam, v in cams.items():
            extra[f'{cam}.views'] = str(v['views'])
            extra[f'{cam}.coverage_percent'] = f'{100 * v["coverage"]:.0f}'
        for pair, n in status['shared_views'].items():
            extra[f'shared_views.{pair}'] = str(n)
        coverage = min(v['coverage'] for v in cams.values()) if cams else 0.0
        return SessionProgress(status['poses'], MIN_VIEWS_PER_CAMERA, coverage, None,
                               status['next'], extra)


def main(args=None):
    """Run the ``rig_calibration`` node."""
    return run(RigCalibrationNode, args, executor='events')
