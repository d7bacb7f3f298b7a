"""
``accelcal p2p-solve`` and ``accelcal study p2p``.

``p2p-solve`` reads JSON lines (stdin or ``--input``), one problem per line::

    {"uv": [[u1, v1], [u2, v2]], "K": [9 row-major], "points": [[X1, Y1, Z1], [X2, Y2, Z2]],
     "down": [gx, gy, gz]}

or ``"roll"``, ``"pitch"`` (rad, REP-103, IMU mounted by ``"imu_to_camera"`` [9], default
camera along body +x) instead of ``"down"``; optional ``"D"`` (distortion, OpenCV
order; then ``uv`` are raw pixels) and ``"id"`` (echoed). It writes one JSON line per
problem: ``{"solutions": [{"R": [9 row-major], "t": [3], "yaw": rad}, ...]}``, or
``{"solutions": [], "error": "..."}``. Blank lines are skipped; a malformed line (bad
JSON, a missing key, a wrong size, NaN, ``K`` without positive focal lengths, a
non-rotation ``imu_to_camera``, emitter coordinates beyond +-1e6 m, a pixel outside the
lens model's valid range...) gets its one-line error and the following lines go
on. ``--imu-to-camera`` (or the ``imu_to_camera`` of ``--rig``'s file) is the mounting
of lines without their own; a bad option or rig file is refused before any line is
read. Exit status 0, or 1 when any line was malformed (not merely without a solution).
"""
import sys
from typing import Any, Dict, Optional, Tuple, TYPE_CHECKING

from accelcal_ros.cli_args import finite_float, float_in, int_in, nonnegative_int

if TYPE_CHECKING:  # pragma: no cover - annotations only
    from accelcal_ros.camera import CameraModel
    import numpy as np

SOLVE_HELP = """\
Solve P2P with known vertical (paper A eq. 8): one JSON problem per input line,
one JSON line of solutions per problem on stdout.

input:  {"uv": [[u1, v1], [u2, v2]], "K": [9 row-major], "points": [[X1, Y1, Z1],
         [X2, Y2, Z2]], "down": [gx, gy, gz]}
        or "roll", "pitch" (rad, REP-103 IMU attitude; "imu_to_camera": [9], default
        camera along body +x) instead of "down"; optional "D" (OpenCV distortion; uv are
        then raw pixels) and "id" (echoed).
output: {"solutions": [{"R": [9 row-major], "t": [3], "yaw": rad}, ...]}
        or {"solutions": [], "error": "..."}

Frames: camera optical (x right, y down, z forward); object z up, metres;
X_cam = R X_obj + t; yaw = heading of the optical axis about object z (from +x to +y).
A malformed line gets its error and the rest go on; exit status 1 if any line was
malformed. --imu-to-camera (or --rig's imu_to_camera) is the mounting of lines with
roll/pitch and no "imu_to_camera" of their own.

example (one problem per line):
  echo '{"uv": [[700, 500], [500, 520]], "K": [1000, 0, 640, 0, 1000, 480, 0, 0, 1], \
"points": [[0, 0, 0], [1, 0, 0]], "down": [0, 0.8, 0.6]}' | accelcal p2p-solve
"""

_PROBLEM_KEYS = {'uv', 'K', 'points', 'down', 'roll', 'pitch', 'D', 'imu_to_camera', 'id'}


def register(subparsers: Any, study_subparsers: Any) -> None:
    """Add ``p2p-solve`` and ``study p2p``."""
    import argparse

    solve = subparsers.add_parser(
        'p2p-solve', help='solve P2P-with-known-vertical problems given as JSON lines',
        formatter_class=argparse.RawDescriptionHelpFormatter, description=SOLVE_HELP)
    solve.add_argument('--input', '-i', default='-', help='input file (default: stdin)')
    solve.add_argument('--rig', metavar='YAML',
                       help="rig file: its imu_to_camera is the lines' default mounting")
    solve.add_argument('--imu-to-camera', type=finite_float, nargs=9, metavar='R',
                       help='rotation IMU body -> camera optical frame, 9 row-major values, '
                            'for lines with roll/pitch and no imu_to_camera (default: the '
                            "--rig file's, else camera along body +x)")
    solve.set_defaults(handler=_solve_main)
    _register_p2p_bag(subparsers)
    study = study_subparsers.add_parser(
        'p2p', help='paper A Table 2: P2P yaw/range errors from calibration tilt errors',
        description='Monte Carlo of paper A Table 2 (P2P yaw and range errors caused by '
                    "tilt errors of the paper's K=300/K=100 calibration sets against the "
                    "K=500 truth, and of the package's own K=12 calibration).")
    study.add_argument('--trials', type=int_in(1, 1000000), default=10000,
                       help='trials (default 10000; at most 1000000)')
    study.add_argument('--seed', type=nonnegative_int, default=0, help='random seed (default 0)')
    study.add_argument('--elevation-deg', type=float_in(0.0, 90.0, True, True),
                       default=30.0,
                       help='camera elevation above the emitters seen from them (default 30)')
    study.add_argument('--package-count', type=int_in(0, 10000), default=100,
                       help='number of K=12 package calibrations (default 100; 0: skip; '
                       'at most 10000)')
    study.add_argument('--no-sweep', action='store_true',
                       help='skip the elevation sweep (geometry dependence)')
    study.add_argument('--json', metavar='PATH', help='also write the figures as JSON')
    study.set_defaults(handler=_study_main)


def _problem_array(problem: dict, key: str, shape: tuple):
    """Return ``problem[key]`` as finite floats of ``shape`` (9 values for 3x3 accepted)."""
    import numpy as np

    from accelcal_ros.errors import InputError

    if key not in problem:
        raise InputError(f'missing "{key}"')
    value = problem[key]

    def numbers_only(item):
        if isinstance(item, (list, tuple)):
            return all(numbers_only(v) for v in item)
        return isinstance(item, (int, float)) and not isinstance(item, bool)

    if not numbers_only(value):
        raise InputError(f'"{key}" must be JSON numbers of shape {shape}, got {value!r:.80}')
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):  # ragged nesting
        raise InputError(f'"{key}" must be numbers of shape {shape}') from None
    if array.shape != shape and not (len(shape) == 2 and array.size == shape[0] * shape[1]
                                     and array.ndim == 1):
        raise InputError(f'"{key}": expected shape {shape}, got {array.shape}')
    if not np.all(np.isfinite(array)):
        raise InputError(f'"{key}" contains NaN or infinity')
    return array.reshape(shape)


def parse_problem(line: str, imu_to_camera: Optional['np.ndarray'] = None
                  ) -> Tuple['np.ndarray', 'CameraModel', 'np.ndarray', 'np.ndarray']:
    """
    Return ``(uv, camera, points, down)`` of one JSON line; InputError if malformed.

    ``camera`` is the :class:`~accelcal_ros.camera.CameraModel` of ``"K"`` (validated:
    focal lengths > 0) and ``"D"`` (0, 4, 5 or 8 values); ``points`` are within
    +-``MAX_COORDINATE_M`` (m). ``down`` comes from ``"down"`` (any finite nonzero
    length, returned divided by its largest absolute component) or from
    ``"roll"``/``"pitch"`` (rad, |roll| <= pi, |pitch| <= pi/2) with the line's
    ``"imu_to_camera"``, else ``imu_to_camera`` (the command's), else the default
    mounting.
    """
    import json
    import math

    from accelcal_ros.camera import CameraModel
    from accelcal_ros.errors import InputError
    from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA
    from accelcal_ros.p2p.solver import down_from_roll_pitch, MAX_COORDINATE_M
    from accelcal_ros.camera.rig import resolve_imu_to_camera
    import numpy as np

    try:
        problem = json.loads(line)
    except ValueError as exc:
        raise InputError(f'not valid JSON: {exc}') from None
    except RecursionError:
        raise InputError('not valid JSON: nested too deeply') from None
    if not isinstance(problem, dict):
        raise InputError('expected a JSON object {"uv": ..., "K": ..., "points": ..., '
                         '"down": ...}')
    unknown = sorted(set(problem) - _PROBLEM_KEYS)
    if unknown:
        raise InputError(f'unknown key(s) {", ".join(unknown)}; expected uv, K, points and '
                         'down (or roll and pitch), optionally D, imu_to_camera, id')
    uv = _problem_array(problem, 'uv', (2, 2))
    k = _problem_array(problem, 'K', (3, 3))
    dist = np.zeros(0)
    if problem.get('D') is not None:
        dist = _problem_array(problem, 'D', (len(problem['D']),)
                              if isinstance(problem['D'], list) else (5,))
    camera = CameraModel(0, 0, k, dist)
    points = _problem_array(problem, 'points', (2, 3))
    if np.abs(points).max() > MAX_COORDINATE_M:
        raise InputError(f'"points": coordinates must be within +-{MAX_COORDINATE_M:,.0f} m '
                         '(emitters in metres in a local object frame)')
    if 'down' in problem:
        if 'roll' in problem or 'pitch' in problem:
            raise InputError('give either "down" or "roll" and "pitch", not both')
        down = _problem_array(problem, 'down', (3,))
        largest = np.abs(down).max()
        if not largest > 0:
            raise InputError('"down" has zero length')
        down = down / largest  # any finite nonzero length: no overflow or underflow
    elif 'roll' in problem and 'pitch' in problem:
        roll = float(_problem_array(problem, 'roll', ()))
        pitch = float(_problem_array(problem, 'pitch', ()))
        if abs(roll) > math.pi + 1e-9 or abs(pitch) > math.pi / 2 + 1e-9:
            raise InputError(f'"roll" must be within +-pi and "pitch" within +-pi/2 (rad, '
                             f'REP-103), got {roll:g}, {pitch:g}')
        mount = DEFAULT_IMU_TO_CAMERA if imu_to_camera is None else imu_to_camera
        if 'imu_to_camera' in problem:
            mount, _ = resolve_imu_to_camera(
                None, _problem_array(problem, 'imu_to_camera', (3, 3)), '"imu_to_camera"')
        down = down_from_roll_pitch(roll, pitch, mount)
    else:
        raise InputError('missing the vertical: give "down" [3] or "roll" and "pitch" (rad)')
    return uv, camera, points, down


def solve_line(line: str, imu_to_camera: Optional['np.ndarray'] = None
               ) -> Tuple[Dict[str, Any], bool]:
    """
    Return ``(output_dict, malformed)`` for one input line (never raises AccelcalError).

    ``imu_to_camera`` (3x3) is the command's mounting, used when the line has none.
    """
    import json

    from accelcal_ros.errors import AccelcalError, InputError
    from accelcal_ros.p2p.beacons import undistort_pixels
    from accelcal_ros.p2p.solver import solve_pixels

    ident = None
    try:
        obj = json.loads(line)
        if isinstance(obj, dict):
            ident = obj.get('id')
    except (ValueError, RecursionError):
        pass
    out = {} if ident is None else {'id': ident}
    try:
        uv, camera, points, down = parse_problem(line, imu_to_camera)
        if camera.has_distortion():
            _, uv = undistort_pixels(uv, camera)
        solutions = solve_pixels(uv, camera.K, points, down)
        out['solutions'] = [s.to_dict() for s in solutions]
        return out, False
    except InputError as exc:
        out.update(solutions=[], error=str(exc))
        return out, True
    except AccelcalError as exc:
        out.update(solutions=[], error=str(exc))
        return out, False


def _solve_main(args):
    import contextlib
    import json

    from accelcal_ros.camera.rig import load_rig, resolve_imu_to_camera
    from accelcal_ros.fileio import open_text_lines

    # a bad rig file or --imu-to-camera is refused up front; a bad line only skips it
    rig = None if args.rig is None else load_rig(args.rig)
    imu_to_camera, _ = resolve_imu_to_camera(rig, args.imu_to_camera)

    # bytes that are not UTF-8 spoil only their line (its JSON error), as on stdin; a file
    # must be a regular file (no device or FIFO: '-' is the way to stream)
    stream = sys.stdin if args.input == '-' else open_text_lines(args.input, 'JSON-lines file')
    status = 0
    with contextlib.closing(stream) if args.input != '-' else contextlib.nullcontext():
        for line in stream:
            if not line.strip():
                continue
            out, malformed = solve_line(line, imu_to_camera)
            if malformed:
                status = 1
            sys.stdout.write(json.dumps(out) + '\n')
            sys.stdout.flush()
    return status


def _study_main(args):
    import json

    from accelcal_ros.errors import InputError
    from accelcal_ros.fileio import write_text_atomic
    from accelcal_ros.p2p import study

    if not 0.0 < args.elevation_deg < 90.0:
        raise InputError(f'--elevation-deg must be in (0, 90), got {args.elevation_deg}')
    geometry = study.StudyGeometry(elevation_deg=args.elevation_deg)
    own = None
    if args.package_count > 0:
        own = args.fit_calibrations(count=args.package_count, seed=args.seed)
    result = study.run_study(args.trials, args.seed, geometry, own)
    sweep = None if args.no_sweep else study.elevation_sweep(
        trials=max(args.trials // 5, 1), seed=args.seed, geometry=geometry)
    print(study.format_table(result, sweep))
    if args.json:
        payload = dict(result, sweep={str(k): v for k, v in (sweep or {}).items()})
        write_text_atomic(args.json, json.dumps(payload, indent=2) + '\n')
    return 0


def _register_p2p_bag(subparsers):
    """``accelcal p2p BAG``: the p2p node's work over a recording."""
    from accelcal_ros.recording.cli_support import add_stamp_argument

    p = subparsers.add_parser(
        'p2p', help='P2P camera poses over a recorded bag (images, CameraInfo, attitude/IMU)',
        description='Run the p2p node over a bag: each image of --image with the first valid '
                    'CameraInfo of --camera-info and the attitude at its stamp (--attitude, '
                    'the Vector3Stamped of the attitude node, or roll/pitch from --imu with '
                    '--calibration); writes one CSV row per image (camera position in the '
                    'object frame, m; yaw, deg; or the reason there is no pose).')
    p.add_argument('bag', metavar='BAG', help='rosbag2 directory, .mcap, .db3 or ROS 1 .bag')
    p.add_argument('--image', metavar='TOPIC', help='sensor_msgs/Image or CompressedImage '
                   'topic (default: the only one)')
    p.add_argument('--camera-info', metavar='TOPIC', help='sensor_msgs/CameraInfo topic')
    p.add_argument('--attitude', metavar='TOPIC', help='geometry_msgs/Vector3Stamped (x roll, '
                   'y pitch, rad) topic of the attitude node')
    p.add_argument('--imu', metavar='TOPIC', help='sensor_msgs/Imu topic: roll/pitch from '
                   'its calibrated accelerometer instead of --attitude')
    p.add_argument('--calibration', metavar='YAML', help='accelerometer calibration for --imu')
    p.add_argument('--emitters', type=finite_float, nargs=6, metavar='M',
                   help='object coordinates of M1 and M2, x1 y1 z1 x2 y2 z2 (m; default: the '
                        "node's 0 0 0 1 0 0)")
    p.add_argument('--imu-to-camera', type=finite_float, nargs=9, metavar='R',
                   help='rotation IMU body -> camera optical frame, 9 row-major values')
    p.add_argument('--threshold', type=int_in(0, 254),
                   help='emitter grey level (default: as the node)')
    add_stamp_argument(p)
    p.add_argument('-o', '--output', required=True, help='CSV of poses to write')
    p.set_defaults(handler=_p2p_bag_main, output_suffixes={'output': ('.csv',)})


def _p2p_bag_main(args):
    from accelcal_ros.errors import InputError
    from accelcal_ros.fileio import write_text_atomic
    from accelcal_ros.p2p.params import P2P_PARAMS
    from accelcal_ros.p2p.pipeline import P2PPipeline
    from accelcal_ros.recording.cli_support import open_bag, warn
    from accelcal_ros.p2p.bag import first_camera_info, results_csv, run_p2p
    from accelcal_ros.recording.streams import attitude_series

    values = {spec.name: spec.default for spec in P2P_PARAMS}
    for name, given in (('emitters', args.emitters), ('imu_to_camera', args.imu_to_camera),
                        ('threshold', args.threshold)):
        if given is not None:
            spec = next(s for s in P2P_PARAMS if s.name == name)
            value, reason = spec.check(list(given) if isinstance(given, list) else given)
            if reason:
                raise InputError(f'--{name.replace("_", "-")}: {reason}')
            values[name] = value
    model = None
    if args.calibration:
        from accelcal_ros.sensor.calibration_file import load_sensor_model

        model = load_sensor_model(args.calibration)
    pipeline = P2PPipeline(values)
    with open_bag(args.bag, args.stamp) as bag:
        info = first_camera_info(bag, args.camera_info)
        reason = pipeline.set_camera_info(info['K'].reshape(-1), info['D'],
                                          info['distortion_model'], info['width'],
                                          info['height'])
        if reason:
            raise InputError(reason)
        t, roll, pitch, warnings = attitude_series(bag, args.attitude, args.imu, model)
        warn(warnings)
        image_warnings: list = []
        text, solved, total = results_csv(run_p2p(bag, pipeline, args.image, (t, roll, pitch),
                                                  image_warnings))
        warn(image_warnings)
    write_text_atomic(args.output, text)
    print(f'{solved} of {total} images solved; wrote {args.output}')
    return 0
