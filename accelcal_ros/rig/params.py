"""Parameters of the ``rig_calibration`` node (pure specifications)."""
from typing import List, Optional

from accelcal_ros.frame_tree import frame_name_params
from accelcal_ros.outputs import default_output, output_validator
from accelcal_ros.paramspec import ParamSpec
from accelcal_ros.rig.board import parse_board_size
from accelcal_ros.session_interface import status_period_spec


def _board_ok(value: str) -> Optional[str]:
    try:
        cols, rows = parse_board_size(value)
    except ValueError as exc:
        return str(exc)
    if (cols + rows) % 2 == 0 or min(cols, rows) < 3:
        return 'inner corners COLSxROWS, at least 3 each, one even and one odd (e.g. 9x6)'
    return None


def _names_ok(value: List[str]) -> Optional[str]:
    if not value or len(set(value)) != len(value) or not all(value):
        return 'give one or more distinct camera names'
    return None


RIG_CALIBRATION_PARAMS = (
    ParamSpec('cameras', ['cam0', 'cam1', 'cam2'], 'camera names: subscribes '
              '<name>/image_raw for each; the first (or reference) carries the IMU',
              kind='string_array', validator=_names_ok, read_only=True),
    ParamSpec('board', '9x6', 'chessboard inner corners COLSxROWS as OpenCV counts them',
              validator=_board_ok, read_only=True),
    ParamSpec('square_m', 0.025, 'chessboard square side', minimum=0.001, maximum=1.0,
              unit='m', read_only=True),
    ParamSpec('capture_dir', default_output('rig_capture'), 'directory of the sessions: '
              'each start makes session_<UTC time>/ in it and writes the poses there '
              '(poseNN/<camera>.png, poseNN/imu.csv); ~ is expanded',
              validator=output_validator(directory=True), read_only=True),
    ParamSpec('output_file', default_output('rig.yaml'), 'rig file written by finish '
              '(report and plot beside it); ~ is expanded',
              validator=output_validator(('.yaml', '.yml'))),
    ParamSpec('reference', '', 'reference camera, one of cameras (empty: the first name)'),
    ParamSpec('calibration_file', '', 'accelerometer calibration applied to the IMU '
              '(empty = none)', read_only=True),
    ParamSpec('auto_capture', True, 'capture a pose each time the rig rests with the board '
              'in view'),
    ParamSpec('min_still_s', 1.0, 'stillness needed before a capture', minimum=0.2,
              maximum=30.0, unit='s'),
    status_period_spec('rig_calibration'),
    *frame_name_params('imu_frame', 'camera_frame_suffix'),
)


def reference_problem(reference: str, cameras: List[str]) -> Optional[str]:
    """Return why ``reference`` is not a camera of the rig (None when it is, or empty)."""
    if reference and reference not in cameras:
        return f'reference {reference!r} is not one of the cameras {", ".join(cameras)}'
    return None
