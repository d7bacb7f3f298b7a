"""
``accelcal georeference`` into a map CRS along a geodetic trajectory.

The trajectory is a CSV or NavSatFix + Imu/Odometry in a bag; the scan a PCD/PLY or a
bag's PointCloud2 topic; the output LAS/LAZ (streamed, :mod:`accelcal_ros.lidar.las`) or
PLY/PCD (float64, x = easting, y = northing, z = ellipsoidal height, absolute
``timestamp``).
"""
import argparse
import os
from typing import Any, List, Optional, TYPE_CHECKING

from accelcal_ros.errors import InputError
import numpy as np

if TYPE_CHECKING:  # (heavy: pyproj, scipy; imported where a command runs)
    from accelcal_ros.lidar.geotraj import MapGeoreferencer

CHUNK_POINTS = 1 << 20
"""Points georeferenced and written at a time from a PCD/PLY scan (memory bound)."""
DEFAULT_MAX_GAP_S = 1.0
"""Longest trajectory gap (s) interpolated across with a geodetic trajectory."""


def add_arguments(g: argparse.ArgumentParser) -> None:
    """Add the geodetic options to ``georeference``."""
    from accelcal_ros.cli_args import float_in

    g.add_argument('--trajectory', metavar='CSV',
                   help='geodetic trajectory t,lat,lon,h,roll,pitch,yaw (deg, WGS84 '
                        'ellipsoidal h): the body in local ENU (yaw 0 = east, CCW), or see '
                        '--heading; output in a map CRS')
    g.add_argument('--heading', choices=('enu', 'ned'), default=None,
                   help='--trajectory angles: enu (REP-103, default) or ned (INS: roll/pitch '
                        'of the forward-right-down body in NED, heading from north, clockwise)')
    g.add_argument('--navsat', metavar='TOPIC',
                   help='bag: sensor_msgs/NavSatFix topic (a geodetic trajectory with the '
                        'orientation of --imu or --odom; NO_FIX dropped)')
    g.add_argument('--imu', metavar='TOPIC',
                   help='bag: sensor_msgs/Imu topic whose orientation (body in ENU) goes with '
                        '--navsat')
    g.add_argument('--crs', metavar='EPSG:NNNN',
                   help='projected CRS of the output (default: WGS 84 / UTM zone of the first '
                        'fix, north or south)')
    g.add_argument('--max-gap-s', type=float_in(0.0, 3600.0, low_open=True), default=None,
                   help='points between two poses further apart than this are dropped, never '
                        'interpolated (s; default %g with a geodetic trajectory, no limit '
                        'with --poses/--odom)' % DEFAULT_MAX_GAP_S)


def _max_gap(args: argparse.Namespace) -> float:
    return DEFAULT_MAX_GAP_S if args.max_gap_s is None else float(args.max_gap_s)


def wants_map(args: argparse.Namespace) -> bool:
    """Return whether the command georeferences into a map CRS (geodetic trajectory)."""
    return bool(args.trajectory or args.navsat)


class MapCloudOutput:
    """Collect georeferenced points into LAS/LAZ (streamed) or PLY/PCD (at the end)."""

    def __init__(self, path: str, geo: 'MapGeoreferencer', data: str = 'binary') -> None:
        from accelcal_ros.lidar.las import is_las_path, is_unix_clock

        self.path = path
        self.geo = geo
        self.data = data
        self.las = is_las_path(path)
        self.unix_clock = is_unix_clock(geo.trajectory.t)
        self.parts: List[np.ndarray] = []
        self.writer: Any = None
        self.count = 0
        ext = os.path.splitext(path)[1].lower()
        if ext not in ('.las', '.laz', '.ply', '.pcd'):
            raise InputError(f'{path}: unknown output extension {ext!r} (.laz, .las, .ply '
                             'or .pcd)')

    def add(self, xyz_map: np.ndarray, times: np.ndarray, records: np.ndarray) -> None:
        """Add georeferenced points with their times and source records (fields)."""
        names = records.dtype.names or ()
        intensity = records['intensity'] if 'intensity' in names else None
        ring = records['ring'] if 'ring' in names else None
        returns = next((records[n] for n in ('return', 'return_number') if n in names), None)
        self.count += len(xyz_map)
        if not self.las:
            from accelcal_ros.lidar.cloud import make_cloud

            self.parts.append(make_cloud(xyz_map, intensity, ring, times, 'timestamp',
                                         double=True))
            return
        if self.writer is None:
            from accelcal_ros.lidar.las import LasCloudWriter

            self.writer = LasCloudWriter(self.path, self.geo.projection.wkt(),
                                         self.geo.origin_m, self.unix_clock, ring is not None,
                                         self.geo.projection.name).__enter__()
        self.writer.write(xyz_map, times, intensity, ring, returns)

    def finish(self) -> None:
        """Write (PLY/PCD) or complete (LAS/LAZ) the file."""
        if self.las:
            if self.writer is not None:
                writer, self.writer = self.writer, None
                writer.__exit__(None, None, None)
            return
        from accelcal_ros.lidar.cloud import write_cloud

        write_cloud(self.path, np.concatenate(self.parts), self.data)

    def abort(self, exc: BaseException) -> None:
        """Discard a half-written LAS/LAZ (nothing reaches the output path)."""
        if self.writer is not None:
            writer, self.writer = self.writer, None
            writer.__exit__(type(exc), exc, exc.__traceback__)

    def time_note(self) -> str:
        """Return the line that says which time system the file holds."""
        if not self.las:
            return 'timestamp: the recording clock (s), as in the input'
        return ('gps_time: Adjusted Standard GPS Time (Unix stamps + leap seconds - 1e9)'
                if self.unix_clock else 'gps_time: the recording clock (s; not GPS time)')


def _no_points(what: str, geo: 'MapGeoreferencer', totals: dict) -> InputError:
    t0, t1 = geo.trajectory.span
    return InputError(f'no point of {what} could be georeferenced (trajectory '
                      f'[{t0:.3f}, {t1:.3f}] s; {totals.get("before_span", 0)} before, '
                      f'{totals.get("after_span", 0)} after, {totals.get("in_gap", 0)} in '
                      'gaps): wrong --time-base, --stamp or trajectory?')


def _summary(totals: dict) -> str:
    return (f'{totals["kept"]} of {totals["total"]} points georeferenced; dropped '
            f'{totals["before_span"]} before and {totals["after_span"]} after the trajectory, '
            f'{totals["in_gap"]} in gaps longer than --max-gap-s, {totals["non_finite"]} '
            'non-finite (never extrapolated)')


def _run(args: argparse.Namespace, geo: 'MapGeoreferencer', feed: Any) -> int:
    from accelcal_ros.recording.cli_support import warn

    for line in geo.report_lines():
        print(line)
    warn(geo.warnings())
    out = MapCloudOutput(args.output, geo, args.data or 'binary')
    try:
        totals, warnings = feed(out)
        if totals['kept'] == 0:
            raise _no_points(args.cloud or args.bag, geo, totals)
        out.finish()
    except BaseException as exc:
        out.abort(exc)
        raise
    warn(warnings)
    print(_summary(totals))
    print(out.time_note())
    print(f'wrote {args.output} ({out.count} points, {geo.projection.name})')
    return 0


def georeference_map(args: argparse.Namespace, boresight: np.ndarray) -> int:
    """Run ``georeference`` with a geodetic trajectory (file scan or bag)."""
    from accelcal_ros.lidar.geotraj import MapGeoreferencer, read_trajectory_csv

    if args.poses:
        raise InputError('give either --poses (local frame) or --trajectory/--navsat '
                         '(geodetic), not both')
    if args.bag:
        return _georeference_bag(args, boresight)
    if not args.cloud or not args.trajectory:
        raise InputError('georeference needs --cloud with --trajectory, or a BAG with --navsat '
                         '(or --trajectory)')
    traj = read_trajectory_csv(args.trajectory, args.heading or 'enu')
    geo = MapGeoreferencer(traj, boresight, args.lever_arm, args.crs, _max_gap(args))
    return _run(args, geo, lambda out: _feed_file(args, geo, out))


def _feed_file(args, geo, out):
    from accelcal_ros.errors import AccelcalError
    from accelcal_ros.lidar.cloud import point_times, read_cloud, xyz

    cloud = read_cloud(args.cloud)
    if len(cloud) == 0:
        raise InputError(f'{args.cloud} holds no points: nothing to georeference')
    try:
        times = point_times(cloud, args.time_base, args.time_field)
    except (AccelcalError, ValueError, TypeError) as exc:
        raise InputError(f'{args.cloud}: {exc}') from None
    totals = {'total': 0, 'kept': 0, 'before_span': 0, 'after_span': 0, 'in_gap': 0,
              'non_finite': 0}
    for a in range(0, len(cloud), CHUNK_POINTS):
        part, t = cloud[a:a + CHUNK_POINTS], times[a:a + CHUNK_POINTS]
        pts, keep, stats = geo.georeference(xyz(part), t)
        for key in totals:
            totals[key] += getattr(stats, key)
        if stats.kept:
            out.add(pts, t[keep], part[keep])
    return totals, []


def _georeference_bag(args: argparse.Namespace, boresight: np.ndarray) -> int:
    from accelcal_ros.lidar.geobag import read_geodetic_trajectory, stream_scans
    from accelcal_ros.lidar.geotraj import MapGeoreferencer, read_trajectory_csv
    from accelcal_ros.recording.cli_support import open_bag

    with open_bag(args.bag, args.stamp) as bag:
        if args.trajectory:
            traj = read_trajectory_csv(args.trajectory, args.heading or 'enu')
        else:
            traj = read_geodetic_trajectory(bag, args.navsat, args.imu, args.odom)
        geo = MapGeoreferencer(traj, boresight, args.lever_arm, args.crs, _max_gap(args))
        return _run(args, geo, lambda out: stream_scans(bag, args.points, geo, out.add,
                                                        args.time_field))


def check_output(path: Optional[str], geodetic: bool) -> None:
    """Refuse LAS/LAZ output without a map CRS (local poses have none)."""
    from accelcal_ros.lidar.las import is_las_path

    if path and is_las_path(path) and not geodetic:
        raise InputError(f'{path}: LAS/LAZ output needs a geodetic trajectory (--trajectory '
                         'or --navsat) for its CRS; local poses give .ply or .pcd')


#: options that only a geodetic trajectory uses (``dest``: option)
GEODETIC_ONLY_OPTIONS = {'crs': '--crs', 'imu': '--imu'}


def refuse_geodetic_options(args: argparse.Namespace) -> None:
    """
    Refuse ``--crs``/``--imu`` without a geodetic trajectory: they would be ignored.

    Local poses (``--poses``, ``--odom``) give points in their own navigation frame, which
    has no map projection; ``--imu`` is the orientation that goes with ``--navsat``.
    """
    if wants_map(args):
        return
    given = [option for dest, option in GEODETIC_ONLY_OPTIONS.items()
             if getattr(args, dest, None) is not None]
    if given:
        names = ' and '.join(given)
        raise InputError(f'{names} {"applies" if len(given) == 1 else "apply"} only to a '
                         'geodetic trajectory (--trajectory or --navsat); --poses/--odom give '
                         'points in their local navigation frame, which has no map CRS: drop '
                         f'{names} or give a geodetic trajectory')


#: options that only a BAG input reads (``dest``: option)
BAG_ONLY_OPTIONS = {'points': '--points', 'odom': '--odom', 'navsat': '--navsat',
                    'imu': '--imu'}


def refuse_unread_options(args: argparse.Namespace) -> None:
    """
    Refuse an option the inputs or the output would ignore, before anything is read.

    A BAG and ``--cloud`` both (one source of scans); a bag topic (``--points``, ``--odom``,
    ``--navsat``, ``--imu``) without a BAG; ``--heading`` without ``--trajectory`` (it is the
    convention of that file's angles); ``--data`` for LAS/LAZ (which has one encoding), or
    ``binary_compressed`` for anything but ``.pcd``. Each was silently ignored.
    """
    if args.bag and args.cloud:
        raise InputError(f'give the scans once: the BAG {args.bag} (its --points topic) or '
                         f'--cloud {args.cloud}, not both')
    if not args.bag:
        given = [option for dest, option in BAG_ONLY_OPTIONS.items()
                 if getattr(args, dest, None) is not None]
        if given:
            raise InputError(f'{" and ".join(given)} name{"s" if len(given) == 1 else ""} '
                             'a topic of a BAG, and no BAG is given: give the BAG, or the '
                             'poses as --poses or --trajectory with --cloud')
    if args.heading is not None and not args.trajectory:
        raise InputError("--heading is the convention of the --trajectory file's angles; "
                         'without --trajectory it is not read: leave it out')
    ext = os.path.splitext(args.output or '')[1].lower()
    if args.data is not None and ext in ('.las', '.laz'):
        raise InputError(f'--data is the encoding of a .pcd or .ply output; {args.output} is '
                         'LAS/LAZ, which has one: leave it out')
    if args.data == 'binary_compressed' and ext != '.pcd':
        raise InputError(f'--data binary_compressed is a PCD encoding; {args.output} is not '
                         '.pcd: write a .pcd, or use binary or ascii')


def add_study(study_subparsers: Any) -> None:
    """Add ``accelcal study georeference`` (ground truth of the UTM path)."""
    from accelcal_ros.cli_args import float_in

    s = study_subparsers.add_parser(
        'georeference', help='georeferencing into UTM against surveyed targets (simulated)',
        description='Simulate a drive with targets at known WGS84 coordinates, georeference '
                    'the scan into UTM and compare with PROJ straight from the truth; also '
                    'the flat shortcuts (no convergence, no scale factor).')
    s.add_argument('--lat-deg', type=float_in(-79.0, 83.0), default=55.75)
    s.add_argument('--lon-deg', type=float_in(-180.0, 180.0), default=37.6)
    s.set_defaults(handler=run_study)


def run_study(args: argparse.Namespace) -> int:
    """Print the target errors of the exact path and of the flat shortcuts."""
    from accelcal_ros.lidar.cloud import xyz
    from accelcal_ros.lidar.geo_sim import flat_shortcut, simulate_drive, target_truth
    from accelcal_ros.lidar.geotraj import MapGeoreferencer

    drive = simulate_drive(args.lat_deg, args.lon_deg)
    geo = MapGeoreferencer(drive.trajectory, drive.boresight, drive.lever_arm_m)
    for line in geo.report_lines():
        print(line)
    truth = target_truth(drive)
    out, keep, _ = geo.georeference(xyz(drive.cloud), drive.cloud['timestamp'])
    err = np.linalg.norm(out - truth[keep], axis=1) * 1000.0
    print(f'{len(err)} targets 5..100 m from the scanner, 30 s drive at 12 m/s, poses at '
          '100 Hz')
    print(f'{"method":<44} {"max mm":>10} {"median mm":>10}')
    print(f'{"exact (ENU of the pose -> ECEF -> PROJ)":<44} {err.max():>10.3f} '
          f'{np.median(err):>10.3f}')
    for conv, scale, name in ((False, False, 'flat: no convergence, no scale factor'),
                              (False, True, 'flat: scale factor, no convergence'),
                              (True, False, 'flat: convergence, no scale factor'),
                              (True, True, 'flat: convergence and scale at the pose')):
        e = np.linalg.norm(flat_shortcut(drive, conv, scale) - truth, axis=1) * 1000.0
        print(f'{name:<44} {e.max():>10.1f} {np.median(e):>10.1f}')
    return 0
