"""
``accelcal p2p-solve`` and ``accelcal study p2p``.

``p2p-solve`` reads JSON lines (stdin or ``--input``), one problem per line::

    {"uv": [[u1, v1], [u2, v2]], "K": [9 row-major], "points": [[X1, Y1, Z1], [X2, Y2, Z2]],
     "down": [gx, gy, gz]}

or ``"roll"``, ``"pitch"`` (rad, REP-103, IMU mounted by ``"imu_to_camera"`` [9], default
camera along body +x) instead of ``"down"``; optional ``"D"`` (distortion, OpenCV
order; then ``uv`` are raw pixels) and ``"id"`` (echoed). It writes one JSON line per
problem: ``{"solutions": [{"R": [9 row-major], "t": [3], "yaw": rad}, ...]}``, or
``{"solutions": [], "error": "..."}``. Blank lines are skipped; a malformed line gets its
error and the following lines go on. Exit status 0, or 1 when any line was malformed
(not merely without a solution).
"""
import sys

from accelcal_ros.cli_args import float_in, nonnegative_int, positive_int

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
malformed.

example (one problem per line):
  echo '{"uv": [[700, 500], [500, 520]], "K": [1000, 0, 640, 0, 1000, 480, 0, 0, 1], \
"points": [[0, 0, 0], [1, 0, 0]], "down": [0, 0.8, 0.6]}' | accelcal p2p-solve
"""

_PROBLEM_KEYS = {'uv', 'K', 'points', 'down', 'roll', 'pitch', 'D', 'imu_to_camera', 'id'}


def register(subparsers, study_subparsers):
    """Add ``p2p-solve`` and ``study p2p``."""
    import argparse

    solve = subparsers.add_parser(
        'p2p-solve', help='solve P2P-with-known-vertical problems given as JSON lines',
        formatter_class=argparse.RawDescriptionHelpFormatter, description=SOLVE_HELP)
    solve.add_argument('--input', '-i', default='-', help='input file (default: stdin)')
    solve.set_defaults(handler=_solve_main)
    study = study_subparsers.add_parser(
        'p2p', help='paper A Table 2: P2P yaw/range errors from calibration tilt errors',
        description='Monte Carlo of paper A Table 2 (P2P yaw and range errors caused by '
                    "tilt errors of the paper's K=300/K=100 calibration sets against the "
                    "K=500 truth, and of the package's own K=12 calibration).")
    study.add_argument('--trials', type=positive_int, default=10000, help='trials (default 10000)')
    study.add_argument('--seed', type=nonnegative_int, default=0, help='random seed (default 0)')
    study.add_argument('--elevation-deg', type=float_in(0.0, 90.0, True, True),
                       default=30.0,
                       help='camera elevation above the emitters seen from them (default 30)')
    study.add_argument('--package-count', type=nonnegative_int, default=100,
                       help='number of K=12 package calibrations (default 100; 0: skip)')
    study.add_argument('--no-sweep', action='store_true',
                       help='skip the elevation sweep (geometry dependence)')
    study.add_argument('--json', metavar='PATH', help='also write the figures as JSON')
    study.set_defaults(handler=_study_main)


def parse_problem(line):
    """
    Return ``(uv, K, points, down, dist_coeffs)`` of one JSON line; InputError if malformed.

    ``down`` comes from ``"down"`` or from ``"roll"``/``"pitch"`` with ``"imu_to_camera"``.
    """
    import json

    from accelcal_ros.errors import InputError
    from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rotation_matrix_from_list
    from accelcal_ros.p2p.solver import down_from_roll_pitch
    import numpy as np

    try:
        problem = json.loads(line)
    except ValueError as exc:
        raise InputError(f'not valid JSON: {exc}') from None
    if not isinstance(problem, dict):
        raise InputError('expected a JSON object {"uv": ..., "K": ..., "points": ..., '
                         '"down": ...}')
    unknown = sorted(set(problem) - _PROBLEM_KEYS)
    if unknown:
        raise InputError(f'unknown key(s) {", ".join(unknown)}; expected uv, K, points and '
                         'down (or roll and pitch), optionally D, imu_to_camera, id')

    def array(key, shape):
        if key not in problem:
            raise InputError(f'missing "{key}"')
        try:
            value = np.asarray(problem[key], dtype=float)
        except (TypeError, ValueError):
            raise InputError(f'"{key}" must be numbers of shape {shape}') from None
        if value.shape != shape and not (shape == (3, 3) and value.shape == (9,)):
            raise InputError(f'"{key}": expected shape {shape}, got {value.shape}')
        if not np.all(np.isfinite(value)):
            raise InputError(f'"{key}" contains NaN or infinity')
        return value.reshape(shape)

    uv = array('uv', (2, 2))
    k = array('K', (3, 3))
    points = array('points', (2, 3))
    if 'down' in problem:
        if 'roll' in problem or 'pitch' in problem:
            raise InputError('give either "down" or "roll" and "pitch", not both')
        down = array('down', (3,))
        if not np.linalg.norm(down) > 0:
            raise InputError('"down" has zero length')
    elif 'roll' in problem and 'pitch' in problem:
        roll = array('roll', ())
        pitch = array('pitch', ())
        mount = DEFAULT_IMU_TO_CAMERA
        if 'imu_to_camera' in problem:
            mount = rotation_matrix_from_list(problem['imu_to_camera'], 'imu_to_camera')
        down = down_from_roll_pitch(float(roll), float(pitch), mount)
    else:
        raise InputError('missing the vertical: give "down" [3] or "roll" and "pitch" (rad)')
    dist = None
    if 'D' in problem:
        try:
            dist = np.asarray(problem['D'], dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise InputError('"D" must be a list of numbers') from None
    return uv, k, points, down, dist


def solve_line(line):
    """Return ``(output_dict, malformed)`` for one input line (never raises AccelcalError)."""
    import json

    from accelcal_ros.camera import CameraModel
    from accelcal_ros.errors import AccelcalError, InputError
    from accelcal_ros.p2p.beacons import undistort_pixels
    from accelcal_ros.p2p.solver import solve_pixels

    ident = None
    try:
        obj = json.loads(line)
        if isinstance(obj, dict):
            ident = obj.get('id')
    except ValueError:
        pass
    out = {} if ident is None else {'id': ident}
    try:
        uv, k, points, down, dist = parse_problem(line)
        if dist is not None and dist.size and dist.any():
            _, uv = undistort_pixels(uv, CameraModel(0, 0, k, dist))
        solutions = solve_pixels(uv, k, points, down)
        out['solutions'] = [s.to_dict() for s in solutions]
        return out, False
    except InputError as exc:
        out.update(solutions=[], error=str(exc))
        return out, True
    except AccelcalError as exc:
        out.update(solutions=[], error=str(exc))
        return out, False


def _solve_main(args):
    import json

    from accelcal_ros.errors import InputError

    try:
        stream = sys.stdin if args.input == '-' else open(args.input)
    except OSError as exc:
        raise InputError(f'cannot read {args.input}: {exc.strerror}') from None
    status = 0
    with stream:
        for line in stream:
            if not line.strip():
                continue
            out, malformed = solve_line(line)
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

    if args.trials < 1:
        raise InputError(f'--trials must be at least 1, got {args.trials}')
    if not 0.0 < args.elevation_deg < 90.0:
        raise InputError(f'--elevation-deg must be in (0, 90), got {args.elevation_deg}')
    geometry = study.StudyGeometry(elevation_deg=args.elevation_deg)
    own = None
    if args.package_count > 0:
        try:
            own = study.package_models(count=args.package_count, seed=args.seed)
        except ImportError as exc:
            print(f'note: the package calibration study is not available ({exc}); '
                  'K=12 row skipped', file=sys.stderr)
    result = study.run_study(args.trials, args.seed, geometry, own)
    sweep = None if args.no_sweep else study.elevation_sweep(
        trials=max(args.trials // 5, 1), seed=args.seed, geometry=geometry)
    print(study.format_table(result, sweep))
    if args.json:
        payload = dict(result, sweep={str(k): v for k, v in (sweep or {}).items()})
        write_text_atomic(args.json, json.dumps(payload, indent=2) + '\n')
    return 0
