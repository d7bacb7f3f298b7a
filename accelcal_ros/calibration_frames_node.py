"""
Node ``calibration_frames``: the package's calibrations on ``/tf_static``.

Reads ``rig_file`` and ``boresight_file`` (and the mount and lever-arm parameters) and
publishes, as tf2_ros's static broadcaster does (one TFMessage, reliable, transient local),
``base_frame`` -> ``imu_frame`` -> the reference camera's optical frame -> every other
camera, and ``imu_frame`` -> ``lidar_frame`` (:mod:`accelcal_ros.frame_tree` says how each
follows from the files). The files are checked every ``poll_period_s``: a new calibration
(modification time, size) is published again; a file that became unreadable or invalid
is reported with its reason and the last good set stays published. A run-time parameter
change is applied only if the whole tree builds (else refused with the reason).
"""
import os

from accelcal_ros.errors import AccelcalError, InputError
from accelcal_ros.frame_tree import CALIBRATION_FRAMES_PARAMS as SPECS
from accelcal_ros.frame_tree import transforms_from_parameters
from accelcal_ros.rosutil.params import ParameterSet
from accelcal_ros.rosutil.runner import run
from accelcal_ros.rosutil.static_tf import StaticBroadcaster
from rclpy.node import Node


def _file_state(path):
    if not path:
        return None
    try:
        st = os.stat(path)
    except OSError:
        return 'missing'
    return (st.st_mtime_ns, st.st_size)


class CalibrationFramesNode(Node):
    """Thin wiring around :func:`accelcal_ros.frame_tree.transforms_from_parameters`."""

    def __init__(self):
        super().__init__('calibration_frames')
        self._broadcaster = StaticBroadcaster(self)
        self._pending = None
        self.params = ParameterSet(self, SPECS, self._on_change)
        self._pending = dict(self.params.values)
        self._states = self._file_states(self._pending)
        self._publish(transforms_from_parameters(self._pending))
        self._bad_state = None
        self.create_timer(self.params['poll_period_s'], self._poll)

    @staticmethod
    def _file_states(values):
        return {k: _file_state(values[k]) for k in ('rig_file', 'boresight_file')}

    def _publish(self, transforms):
        self._broadcaster.send(transforms, replace=True)
        self.get_logger().info(f'published {len(transforms)} transforms on /tf_static: ' +
                               ', '.join(f'{t.parent} -> {t.child}' for t in transforms))

    def _on_change(self, name, value):
        if self._pending is None:       # declaring: nothing published yet
            return
        values = dict(self._pending)
        values[name] = value
        try:
            transforms = transforms_from_parameters(values)
        except AccelcalError as exc:
            raise InputError(str(exc)) from None
        self._pending = values
        self._states = self._file_states(values)
        self._publish(transforms)

    def _poll(self):
        states = self._file_states(self._pending)
        if states == self._states or states == self._bad_state:
            return
        try:
            transforms = transforms_from_parameters(self._pending)
        except AccelcalError as exc:
            self._bad_state = states
            self.get_logger().error(f'calibration file changed but is not usable ({exc}); '
                                    'the previous transforms stay published')
            return
        self._states, self._bad_state = states, None
        self.get_logger().info('calibration file changed: publishing the new transforms')
        self._publish(transforms)


def main(args=None):
    """Run the ``calibration_frames`` node."""
    return run(CalibrationFramesNode, args, executor='single')
