"""Command line of rig calibration: ``accelcal rig-calibrate`` and ``accelcal study rig``."""
import argparse
import os
from typing import List, Optional, Tuple, TYPE_CHECKING

from accelcal_ros.cli_args import float_in, int_in, nonnegative_int

if TYPE_CHECKING:  # pragma: no cover - annotations only
    from accelcal_ros.rig.board import Board
    from accelcal_ros.rig.calibrate import RigCalibration
    from accelcal_ros.sensor.model import SensorModel


def register(subparsers: argparse._SubParsersAction,
             study_subparsers: argparse._SubParsersAction) -> None:
    """Add the rig subcommands to the ``accelcal`` parser."""
    p = subparsers.add_parser(
        'rig-calibrate', help='camera intrinsics, rig rotations R_0i and imu_to_camera',
        description='Calibrate a camera rig from DIR/poseNN/<camera>.png (a chessboard lying '
                    'on a floor or table, seen by one or more cameras) and DIR/poseNN/imu.csv '
                    '(t,ax,ay,az in s and m/s^2, rig still). Writes the rig file (the '
                    "stitcher's format plus imu_to_camera), <stem>_report.yaml and <stem>.png. "
                    'A bag instead: the still periods of its IMU are the poses, each with the '
                    'frame set of its image topics nearest the middle of the period.')
    p.add_argument('directory', metavar='DIR_OR_BAG',
                   help='capture directory, or a bag (rosbag2 directory, .mcap, .db3, ROS 1 '
                        '.bag) with the image topics and the IMU; still poses are found '
                        'from the IMU')
    _add_bag_arguments(p)
    p.add_argument('--board', required=True, metavar='COLSxROWS',
                   help='inner corners as OpenCV counts them, e.g. 9x6 (one even, one odd)')
    p.add_argument('--square-m', required=True, type=float_in(0.001, 10.0),
                   help='square side (m, 0.001 .. 10)')
    p.add_argument('-o', '--output', required=True, help='rig file (YAML) to write')
    p.add_argument('--intrinsics', nargs='+', default=[], metavar='FILE',
                   help='camera_info YAML files (ROS camera_calibration) held fixed; matched '
                        'to cameras by camera_name or file name')
    p.add_argument('--calibration', metavar='FILE',
                   help='accelerometer calibration file (accelcal calibrate) applied to the '
                        'IMU logs before averaging')
    p.add_argument('--reference', metavar='NAME',
                   help='reference camera (carries the IMU; default: first name in order)')
    p.add_argument('--level-board', action='store_true',
                   help='take the board as level instead of estimating its tilt')
    p.set_defaults(handler=_calibrate, file_outputs=frozenset({'output'}),
                   output_suffixes={'output': ('.yaml', '.yml')})

    s = study_subparsers.add_parser(
        'rig', help='rig calibration accuracy against the number of poses',
        description='Render a 3-camera ring (known K, D, R_0i, imu_to_camera, 0.4 deg board '
                    'tilt), calibrate it from the first N poses and print the errors.')
    s.add_argument('--poses', type=int_in(1, 10000), nargs='+', default=[10, 20, 30, 45])
    s.add_argument('--seed', type=nonnegative_int, default=1)
    s.set_defaults(handler=_study)


def _add_bag_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``rig-calibrate BAG``: topics, frame-set tolerance, still time, export."""
    from accelcal_ros.recording.cli_support import add_stamp_argument

    p.add_argument('--images', dest='image_topics', nargs='+', metavar='TOPIC',
                   help='bag: image topics (sensor_msgs/Image or CompressedImage), one per '
                        'camera, named after the topic (/cam0/image_raw: cam0); default: '
                        'every image topic')
    p.add_argument('--imu', dest='imu_topic', metavar='TOPIC',
                   help='bag: sensor_msgs/Imu topic (default: the only one)')
    p.add_argument('--sync-s', type=float_in(0.0, 10.0, low_open=True), default=0.05,
                   help='bag: largest spread of the stamps of one frame set (s)')
    p.add_argument('--min-still-s', type=float_in(0.0, 3600.0, low_open=True), default=1.0,
                   help='bag: shortest still period taken as a pose (s)')
    p.add_argument('--export', metavar='DIR',
                   help='bag: also keep the extracted capture directory (poseNN/<camera>.png, '
                        'imu.csv) here; it must not exist')
    add_stamp_argument(p)


def _inputs(args: argparse.Namespace) -> List[str]:
    """Return what the command reads: the capture or bag, the calibration, the intrinsics."""
    return [p for p in [args.directory, args.calibration, *args.intrinsics] if p]


def _sensor_model(args: argparse.Namespace) -> 'Optional[SensorModel]':
    if not args.calibration:
        return None
    from accelcal_ros.sensor.calibration_file import load_sensor_model

    return load_sensor_model(args.calibration)


def _calibrate_bag(args: argparse.Namespace, board: 'Board',
                   tmp: str) -> 'Tuple[RigCalibration, str]':
    """Extract the still poses of a bag into ``tmp`` and calibrate them; return the capture."""
    from accelcal_ros.recording.cli_support import open_bag, warn
    from accelcal_ros.rig.bag import capture_topics, extract_capture
    from accelcal_ros.rig.calibrate import calibrate_directory
    from accelcal_ros.rig.report import check_outputs

    directory = os.path.join(tmp, 'capture')
    with open_bag(args.directory, args.stamp) as bag:
        _, cameras = capture_topics(bag, args.image_topics)
        check_outputs(args.output, cameras, _inputs(args), args.export)  # before any work
        model = _sensor_model(args)
        capture = extract_capture(bag, args.image_topics, args.imu_topic, directory,
                                  args.sync_s, args.min_still_s)
    warn(capture.warnings)
    for topic, name in zip(capture.topics, capture.cameras):
        print(f'camera {name}: {topic}')
    for line in capture.spans:
        print(line)
    result = calibrate_directory(directory, board, args.intrinsics, model,
                                 args.reference, estimate_tilt=not args.level_board)
    result.dropped_poses.update(capture.dropped)
    return result, directory


def _publish_export(capture: str, export: str) -> List[str]:
    """
    Copy the extracted capture to ``export`` as a whole (a hidden name, then renamed).

    Return the missing parents it made (outermost first) and ``export`` last, for
    :func:`_remove_made` should a later step fail; a failure here leaves nothing.
    """
    import shutil

    from accelcal_ros.errors import InputError

    from accelcal_ros.fileio import missing_folders

    target = os.path.abspath(export)
    parents = missing_folders(os.path.dirname(target))
    partial = os.path.join(os.path.dirname(target),
                           f'.{os.path.basename(target)}.partial-{os.getpid()}')
    made: List[str] = []
    try:
        for folder in parents:
            os.mkdir(folder)
            made.append(folder)
        shutil.copytree(capture, partial)
        if os.path.lexists(target):
            raise InputError(f'--export {export} appeared while the rig was calibrated; '
                             'name a new folder')
        os.rename(partial, target)
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        _remove_made(made, None)
        raise
    return made + [target]


def _remove_made(parents: List[str], export: Optional[str]) -> None:
    """Remove the ``export`` this run made (whole), then the parents it made if empty."""
    import shutil

    from accelcal_ros.fileio import remove_empty_folders

    if export is not None:
        shutil.rmtree(export, ignore_errors=True)
    remove_empty_folders(parents)


def _calibrate(args: argparse.Namespace) -> int:
    """
    Calibrate; every output (rig file, report, plot, camera_info, export) checked first.

    A failure leaves nothing written: the outputs are written last, the export is made
    whole just before them and removed again if they fail.
    """
    import tempfile

    from accelcal_ros.errors import InputError
    from accelcal_ros.recording.bag import is_bag
    from accelcal_ros.rig.board import Board, parse_board_size
    from accelcal_ros.rig.calibrate import calibrate_directory
    from accelcal_ros.rig.dataset import scan_directory
    from accelcal_ros.rig.report import check_outputs, report_lines, write_outputs

    cols, rows = parse_board_size(args.board)
    board = Board(cols, rows, args.square_m)
    with tempfile.TemporaryDirectory(prefix='accelcal_rig_') as tmp:
        capture = None
        if is_bag(args.directory):
            result, capture = _calibrate_bag(args, board, tmp)
        else:
            if args.export:
                raise InputError(f'--export is for a bag; {args.directory} is a capture '
                                 'directory already')
            cameras = scan_directory(args.directory, args.reference).cameras
            check_outputs(args.output, cameras, _inputs(args))   # before any work
            result = calibrate_directory(args.directory, board, args.intrinsics,
                                         _sensor_model(args), args.reference,
                                         estimate_tilt=not args.level_board)
        for line in report_lines(result):
            print(line)
        made = _publish_export(capture, args.export) if capture and args.export else []
        try:
            paths = write_outputs(args.output, result)
        except BaseException:
            if made:
                _remove_made(made[:-1], made[-1])
            raise
    for path in paths:
        print(f'wrote {path}')
    if made:
        print(f'wrote {args.export} (the capture directory)')
    return 0


def _study(args: argparse.Namespace) -> int:
    from accelcal_ros.rig.study import run_study

    for line in run_study(args.poses, args.seed):
        print(line)
    return 0
