"""
Node ``rig_calibration``: calibrate a camera rig and its IMU mounting live (issue 12).

Like camera_calibration: subscribes ``<camera>/image_raw`` (sensor_msgs/Image) for each
name in ``cameras`` and ``imu/data_raw`` (sensor_msgs/Imu, m/s^2, REP-145), both best
effort. A pose is captured automatically each time the rig rests for ``min_still_s``
with the board in view (:class:`accelcal_ros.rig.capture.RigCapture`), or on
``rig_calibration/capture`` (std_srvs/Trigger); ``rig_calibration/finish`` (Trigger)
calibrates the captured poses and writes ``output_file`` (the stitcher's rig file with
``imu_to_camera``), its report and plot. ``rig_calibration/status`` (std_msgs/String,
YAML) says per camera how many views and how much of the image they cover, per pair how
many shared views, and what to do next.
"""
import threading

from accelcal_ros.errors import AccelcalError
from accelcal_ros.fileio import dump_yaml
from accelcal_ros.rig.params import RIG_CALIBRATION_PARAMS as SPECS
from accelcal_ros.rosutil.drops import DropCounter
from accelcal_ros.rosutil.images import image_msg_to_array
from accelcal_ros.rosutil.params import ParameterSet
from accelcal_ros.rosutil.runner import run
from accelcal_ros.rosutil.stamps import stamp_to_seconds
import numpy as np
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image, Imu
from std_msgs.msg import String
from std_srvs.srv import Trigger


class RigCalibrationNode(Node):
    """Thin wiring around :class:`~accelcal_ros.rig.capture.RigCapture`."""

    def __init__(self):
        super().__init__('rig_calibration')
        self.params = ParameterSet(self, SPECS, self._on_change)
        from accelcal_ros.rig.board import Board, parse_board_size
        from accelcal_ros.rig.capture import RigCapture

        p = self.params
        self._model = None
        if p['calibration_file']:
            from accelcal_ros.sensor.calibration_file import load_sensor_model

            self._model = load_sensor_model(p['calibration_file'])
        board = Board(*parse_board_size(p['board']), p['square_m'])
        self._lock = threading.Lock()
        self._capture = RigCapture(p['capture_dir'], list(p['cameras']), board,
                                   p['auto_capture'], p['min_still_s'])
        sensor_qos = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT,
                                history=HistoryPolicy.KEEP_LAST)
        imu_qos = QoSProfile(depth=2000, reliability=ReliabilityPolicy.BEST_EFFORT,
                             history=HistoryPolicy.KEEP_LAST)
        for name in p['cameras']:
            self.create_subscription(Image, f'{name}/image_raw',
                                     lambda msg, cam=name: self._on_image(cam, msg), sensor_qos)
        self.create_subscription(Imu, 'imu/data_raw', self._on_imu, imu_qos)
        self.create_service(Trigger, 'rig_calibration/capture', self._on_capture)
        self.create_service(Trigger, 'rig_calibration/finish', self._on_finish)
        self._status = self.create_publisher(String, 'rig_calibration/status', 10)
        self.create_timer(p['status_period_s'], self._publish_status)
        self._warned = set()
        self._drops = DropCounter(self)

    def _on_change(self, name, value):
        with self._lock:
            if name == 'auto_capture':
                self._capture.auto = bool(value)
            elif name == 'min_still_s':
                self._capture.min_still_s = float(value)

    def _warn_once(self, key, text):
        if key not in self._warned:
            self._warned.add(key)
            self.get_logger().warning(text)

    def _on_image(self, camera, msg):
        try:
            grey = image_msg_to_array(msg, want='mono8', topic=f'{camera}/image_raw')
        except AccelcalError as exc:
            self._drops.drop(f'{camera}_images', f'unusable image ignored: {exc}')
            return
        with self._lock:
            self._capture.add_image(camera, stamp_to_seconds(msg.header.stamp), grey)

    def _on_imu(self, msg):
        a = msg.linear_acceleration
        accel = np.array([a.x, a.y, a.z])
        if not np.all(np.isfinite(accel)):
            self._drops.drop('imu_samples', 'IMU sample with NaN ignored')
            return
        with self._lock:
            name = self._capture.add_imu(stamp_to_seconds(msg.header.stamp), accel)
        if name:
            self.get_logger().info(f'captured {name} ({len(self._capture.poses)} poses)')

    def _publish_status(self):
        with self._lock:
            status = self._capture.status()
        self._status.publish(String(data=dump_yaml(status)))

    def _on_capture(self, request, response):
        with self._lock:
            response.success, response.message = self._capture.capture()
        return response

    def _on_finish(self, request, response):
        from accelcal_ros.rig.report import report_lines, write_outputs

        p = dict(self.params.values)
        try:
            with self._lock:
                result = self._capture.finish(p['reference'] or None, self._model)
            paths = write_outputs(p['output_file'], result)
        except (AccelcalError, OSError) as exc:
            response.success = False
            response.message = f'calibration failed: {exc}'
            self.get_logger().error(response.message)
            return response
        for line in report_lines(result):
            self.get_logger().info(line)
        response.success = True
        response.message = (f'{len(result.cameras)} cameras, rig fit RMS '
                            f'{result.fit.rms_px:.3f} px, {len(result.warnings)} warnings; '
                            f'wrote {", ".join(paths)}')
        return response


def main(args=None):
    """Run the ``rig_calibration`` node."""
    return run(RigCalibrationNode, args, executor='events')
