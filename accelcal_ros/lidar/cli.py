"""
Command line of the LiDAR feature (paper B).

``accelcal boresight``, ``accelcal georeference``, ``accelcal error-budget`` and
``accelcal study boresight``.
"""
import argparse

from accelcal_ros.cli_args import angle_deg, finite_float, float_in, int_in, positive_int


def register(subparsers: argparse._SubParsersAction,
             study_subparsers: argparse._SubParsersAction) -> None:
    """Add the LiDAR subcommands to the ``accelcal`` parser."""
    p = subparsers.add_parser(
        'boresight', help='LiDAR-IMU boresight from static positions (paper B)',
        description='Calibrate the rotation LiDAR -> IMU from DIR/posNN.pcd|ply + '
                    'DIR/posNN_imu.csv (one pair per static position): gravity from the '
                    'accelerometer paired with the floor normal from the cloud (Wahba).')
    p.add_argument('directory', metavar='DIR|BAG',
                   help='directory of posNN files, or one continuous recording (rosbag2 '
                        'directory, .mcap, .db3, ROS 1 .bag) with --points and --imu')
    _add_boresight_bag_arguments(p)
    p.add_argument('-o', '--output', required=True, help='boresight YAML to write')
    p.add_argument('--prior-rpy-deg', nargs=3, type=angle_deg(360.0), metavar=('R', 'P', 'Y'),
                   help='nominal mounting (LiDAR -> IMU, REP-103 fixed axes, deg); guides '
                        'the floor search. Without it the floor is the plane consistent '
                        'with one rotation across all positions')
    p.add_argument('--calibration', metavar='FILE',
                   help='accelerometer calibration file (accelcal calibrate) applied to '
                        'the IMU logs before averaging')
    p.add_argument('--weighting', choices=('noise', 'equal'), default='equal',
                   help="pair weights: equal (paper, default) or from each pair's noise")
    p.add_argument('--distance-threshold-m', type=float_in(0.0, 100.0, low_open=True),
                   default=0.05,
                   help='MSAC inlier distance (default 0.05 m)')
    p.add_argument('--max-tilt-deg', type=float_in(0.0, 90.0, low_open=True),
                   default=15.0,
                   help='gravity-guided search: floor normal within this of the expected '
                        'up (default 15 deg)')
    p.add_argument('--max-range-m', type=float_in(0.0, 1e4, low_open=True), default=30.0,
                   help='crop radius (m)')
    p.add_argument('--voxel-m', type=float_in(0.0, 100.0), default=0.0,
                   help='thinning voxel (m, 0 = off)')
    p.add_argument('--ceiling-lift-m', type=float_in(0.0, 1e4), default=10.0,
                   help='paper B ceiling removal: lift the origin this far up ...')
    p.add_argument('--ceiling-radius-m', type=float_in(0.0, 1e4), default=0.0,
                   help='... and drop points within this radius of it (0: instead drop '
                        'points higher than --max-height-m above the scanner)')
    p.add_argument('--max-height-m', type=float_in(-1e4, 1e4), default=-0.2,
                   help='floor candidates lie below this height along up (m, default -0.2)')
    p.add_argument('--skip-bad-files', action='store_true',
                   help='drop positions whose files cannot be read instead of failing')
    p.add_argument('--plot', metavar='PNG', help='also draw the per-position errors')
    p.set_defaults(handler=_boresight, file_outputs=frozenset({'output'}),
                   output_suffixes={'output': ('.yaml', '.yml')})

    g = subparsers.add_parser(
        'georeference', help='place LiDAR points in the navigation frame or a map CRS (UTM)',
        description='p_nav = C(t) (R p_lidar + lever) + r(t) with the pose interpolated to '
                    "each point's time (linear position, slerp orientation). With a geodetic "
                    'trajectory (--trajectory CSV, or --navsat + --imu/--odom in a bag) each '
                    'point goes through the ENU frame of its pose to ECEF and the map '
                    'projection (PROJ): UTM of the first fix or --crs; .laz/.las carry the CRS.')
    g.add_argument('--cloud', help='scan (.pcd/.ply) with per-point time (a recording: give '
                                   'it as BAG)')
    g.add_argument('--poses', help='CSV t,x,y,z,qx,qy,qz,qw (IMU -> nav; or --odom)')
    _add_georeference_bag_arguments(g)
    g.add_argument('--boresight', required=True, help='boresight YAML (R or rpy_deg)')
    g.add_argument('--lever-arm', nargs=3, type=float_in(-1e4, 1e4), default=(0.0, 0.0, 0.0),
                   metavar=('X', 'Y', 'Z'), help='LiDAR origin in the IMU frame (m)')
    g.add_argument('--time-base', type=finite_float, default=0.0,
                   help='scan start (s, pose clock) added to relative point times '
                        '(fields time, t); absolute "timestamp" fields are used as is')
    g.add_argument('--time-field', help='per-point time field (default: time, t or '
                                        'timestamp)')
    g.add_argument('--data', choices=('binary', 'ascii', 'binary_compressed'),
                   default=None, help='output encoding of .pcd/.ply (default binary; '
                                      'binary_compressed: PCD only)')
    g.add_argument('-o', '--output', required=True,
                   help='output cloud (.ply or .pcd; .laz or .las with a geodetic trajectory)')
    from accelcal_ros.lidar.geo_cli import add_arguments as add_geodetic_arguments

    add_geodetic_arguments(g)
    g.set_defaults(handler=_georeference, file_outputs=frozenset({'output'}))

    e = subparsers.add_parser(
        'error-budget', help='theoretical point error, paper B eq. (1)',
        description='sqrt(D_ins^2 + D_gnss^2 + D_lidar^2 + D_boresight^2) at a range.')
    e.add_argument('--range-m', type=float_in(0.0, 1e6), default=100.0)
    e.add_argument('--attitude-deg', type=float_in(0.0, 90.0, high_open=True), default=0.1,
                   help='INS attitude error, deg (0 to < 90; default 0.1)')
    e.add_argument('--gnss-m', type=float_in(0.0, 1e6), default=0.01)
    e.add_argument('--lidar-m', type=float_in(0.0, 1e6), default=0.03)
    e.add_argument('--boresight-deg', type=float_in(0.0, 90.0, high_open=True), nargs='+',
                   default=[1.0, 0.3], help='boresight errors, deg (0 to < 90; default 1 0.3)')
    e.add_argument('--sync-s', type=float_in(0.0, 3600.0), default=0.0,
                   help='time-sync error (s)')
    e.add_argument('--speed-m-s', type=float_in(0.0, 1e4), default=30 / 3.6)
    e.add_argument('--rate-deg-s', type=float_in(0.0, 1e5), default=180.0)
    e.set_defaults(handler=_error_budget)

    s = study_subparsers.add_parser(
        'boresight', help='boresight error on the simulated 15-position protocol',
        description='Simulate the protocol of paper B (VLP-16 in a room, known boresight) '
                    'for several seeds and report the error of the recovered rotation.')
    s.add_argument('--trials', type=int_in(1, 100), default=5,
                   help='simulated protocols (default 5; at most 100)')
    s.add_argument('--no-prior', action='store_true', help='search the floor without prior')
    s.add_argument('--weighting', choices=('noise', 'equal'), default='equal')
    s.set_defaults(handler=_study)
    from accelcal_ros.lidar.geo_cli import add_study

    add_study(study_subparsers)


def _add_boresight_bag_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``boresight BAG``: topics, stamps, scans per still period."""
    from accelcal_ros.recording.cli_support import add_stamp_argument

    p.add_argument('--points', metavar='TOPIC',
                   help='bag: sensor_msgs/PointCloud2 topic (default: the only one)')
    p.add_argument('--imu', metavar='TOPIC',
                   help='bag: sensor_msgs/Imu topic (default: the only one); its gyro, when '
                        'provided, else its accelerometer, finds the still periods')
    p.add_argument('--clouds-per-position', type=positive_int, default=1,
                   help='bag: scans nearest the middle of each still period used (default 1)')
    add_stamp_argument(p)


def _boresight_from_bag(args, prior, model):
    """Boresight of one continuous recording (positions from its still periods)."""
    from accelcal_ros.errors import CalibrationError
    from accelcal_ros.lidar.boresight import calibrate_boresight
    from accelcal_ros.recording.cli_support import open_bag, warn
    from accelcal_ros.lidar.bag import collect_positions

    with open_bag(args.directory, args.stamp) as bag:
        positions, dropped, spans, warnings = collect_positions(
            bag, args.points, args.imu, model, args.clouds_per_position)
    warn(warnings)
    for line in spans:
        print(line)
    if not positions:
        reasons = '; '.join(f'{k}: {v}' for k, v in dropped.items())
        raise CalibrationError(f'no usable position in {args.directory}: {reasons}')
    result = calibrate_boresight(positions, prior=prior, search=_search_from(args),
                                 weighting=args.weighting)
    merged = dict(dropped)
    merged.update(result.dropped)
    result.dropped = merged
    return result


def _add_georeference_bag_arguments(g: argparse.ArgumentParser) -> None:
    """Options of ``georeference BAG``."""
    from accelcal_ros.recording.cli_support import add_stamp_argument

    g.add_argument('bag', nargs='?', metavar='BAG',
                   help='recording (rosbag2 directory, .mcap, .db3, ROS 1 .bag) with the scans '
                        '(--points) and the poses (--odom, or --poses CSV)')
    g.add_argument('--points', metavar='TOPIC',
                   help='bag: sensor_msgs/PointCloud2 topic (default: the only one)')
    g.add_argument('--odom', metavar='TOPIC',
                   help='bag: nav_msgs/Odometry topic, pose of the IMU in the nav frame '
                        '(default: the only one, unless --poses is given)')
    add_stamp_argument(g)


def _georeference_bag(args: argparse.Namespace) -> int:
    """Georeference every scan of a bag's PointCloud2 topic into one cloud."""
    from accelcal_ros.lidar.boresight import load_boresight
    from accelcal_ros.lidar.cloud import write_cloud
    from accelcal_ros.lidar.poses import PoseStream, read_poses_csv
    from accelcal_ros.recording.cli_support import open_bag, warn
    from accelcal_ros.lidar.bag import georeference_scans
    from accelcal_ros.recording.streams import read_odometry

    boresight = load_boresight(args.boresight)
    with open_bag(args.bag, args.stamp) as bag:
        if args.poses and not args.odom:
            poses = read_poses_csv(args.poses)
        else:
            odom = read_odometry(bag, args.odom)
            warn(odom.warnings)
            poses = PoseStream(odom.t, odom.position, odom.quat)
        cloud, totals, warnings = georeference_scans(bag, args.points, poses, boresight,
                                                     args.lever_arm, args.time_field,
                                                     args.max_gap_s)
    warn(warnings)
    write_cloud(args.output, cloud, args.data or 'binary')
    print(f'{totals["kept"]} of {totals["total"]} points georeferenced; dropped '
          f'{totals["before_span"]} before and {totals["after_span"]} after the pose stream, '
          f'{totals["in_gap"]} in gaps longer than --max-gap-s, {totals["non_finite"]} '
          'non-finite')
    print(f'wrote {args.output}')
    return 0


def _search_from(args):
    from accelcal_ros.lidar.plane_fit import FloorSearch

    search = FloorSearch(voxel_m=args.voxel_m, max_range_m=args.max_range_m,
                         ceiling_lift_m=args.ceiling_lift_m,
                         ceiling_radius_m=args.ceiling_radius_m, max_height_m=args.max_height_m,
                         max_tilt_deg=args.max_tilt_deg,
                         distance_threshold_m=args.distance_threshold_m)
    search.check()
    return search


def _boresight(args: argparse.Namespace) -> int:
    from accelcal_ros.frames import rotation_from_rpy_radians
    from accelcal_ros.lidar.calibrate_dir import (calibrate_directory, plot_errors,
                                                  report_lines, write_result)
    from accelcal_ros.outputs import check_output_path, PNG_SUFFIXES
    from accelcal_ros.recording.bag import is_bag
    import numpy as np

    if args.plot:
        check_output_path(args.plot, '--plot', PNG_SUFFIXES)
    prior = None
    if args.prior_rpy_deg is not None:
        prior = rotation_from_rpy_radians(*np.radians(args.prior_rpy_deg))
    model = None
    if args.calibration:
        from accelcal_ros.sensor.calibration_file import load_sensor_model

        model = load_sensor_model(args.calibration)
    if is_bag(args.directory):
        result = _boresight_from_bag(args, prior, model)
    else:
        result = calibrate_directory(args.directory, prior, model, _search_from(args),
                                     args.weighting, args.skip_bad_files)
    for line in report_lines(result):
        print(line)
    write_result(args.output, result, {'prior_rpy_deg': list(args.prior_rpy_deg)
                                       if args.prior_rpy_deg else None})
    print(f'wrote {args.output}')
    if args.plot:
        plot_errors(args.plot, result)
        print(f'wrote {args.plot}')
    return 0


def _georeference(args: argparse.Namespace) -> int:
    from accelcal_ros.lidar import geo_cli

    geo_cli.check_output(args.output, geo_cli.wants_map(args))
    geo_cli.refuse_geodetic_options(args)
    geo_cli.refuse_unread_options(args)
    if geo_cli.wants_map(args):
        from accelcal_ros.lidar.boresight import load_boresight

        return geo_cli.georeference_map(args, load_boresight(args.boresight))
    if args.bag:
        return _georeference_bag(args)
    if not args.cloud or not args.poses:
        from accelcal_ros.errors import InputError

        raise InputError('georeference needs --cloud and --poses, or a BAG with --points and '
                         '--odom (or --poses)')
    from accelcal_ros.lidar.boresight import load_boresight
    from accelcal_ros.lidar.cloud import make_cloud, point_times, read_cloud, write_cloud, xyz
    from accelcal_ros.lidar.georef import georeference
    from accelcal_ros.lidar.poses import read_poses_csv
    import numpy as np

    boresight = load_boresight(args.boresight)
    poses = read_poses_csv(args.poses)
    cloud = read_cloud(args.cloud)
    if len(cloud) == 0:
        from accelcal_ros.errors import InputError

        raise InputError(f'{args.cloud} holds no points: nothing to georeference')
    from accelcal_ros.errors import AccelcalError, InputError

    try:
        times = point_times(cloud, args.time_base, args.time_field)
    except (AccelcalError, ValueError, TypeError) as exc:   # missing or non-numeric field
        raise InputError(f'{args.cloud}: {exc}') from None
    pts, keep, stats = georeference(xyz(cloud), times, poses, boresight, args.lever_arm,
                                    max_gap_s=args.max_gap_s)
    if stats.kept == 0:
        from accelcal_ros.errors import InputError

        t0, t1 = poses.span
        raise InputError(f'no point of {args.cloud} lies in the span of the pose stream '
                         f'[{t0:.3f}, {t1:.3f}] s (points {np.nanmin(times):.3f}..'
                         f'{np.nanmax(times):.3f} s): wrong --time-base?')
    names = cloud.dtype.names or ()
    out = make_cloud(pts, cloud['intensity'][keep] if 'intensity' in names else None,
                     cloud['ring'][keep] if 'ring' in names else None, times[keep],
                     'timestamp', double=True)
    write_cloud(args.output, out, args.data or 'binary')
    print(stats.summary())
    print(f'wrote {args.output}')
    return 0


def _error_budget(args: argparse.Namespace) -> int:
    from accelcal_ros.lidar.error_budget import error_budget, paper_totals_m, sync_error_m

    sync = sync_error_m(args.sync_s, args.speed_m_s, args.rate_deg_s, args.range_m) \
        if args.sync_s else 0.0
    print(f'paper B eq. (1) at {args.range_m:g} m:')
    for bore in args.boresight_deg:
        t = error_budget(args.range_m, args.attitude_deg, args.gnss_m, args.lidar_m, bore, sync)
        print(f'  boresight {bore:g} deg: attitude {t["attitude"]:.3f} m, GNSS {t["gnss"]:.3f} '
              f'm, LiDAR {t["lidar"]:.3f} m, boresight {t["boresight"]:.3f} m'
              + (f', sync {sync * 1000:.2f} mm' if sync else '') + f' -> {t["total"]:.3f} m')
    before, after = paper_totals_m()
    print(f'  with the printed terms of the paper (18, 1, 3, 175 / 53 cm): {before:.2f} m before, '
          f'{after:.2f} m after calibration (paper: 1.76 m and 0.56 m)')
    return 0


def _study(args: argparse.Namespace) -> int:
    from accelcal_ros.lidar import scanner_sim as sim
    from accelcal_ros.lidar.boresight import calibrate_boresight
    from accelcal_ros.lidar.wahba import rotation_angle_deg
    import numpy as np

    truth = sim.default_boresight()
    errs, means = [], []
    from accelcal_ros.recording.progress import track

    for seed in track(range(args.trials), 'boresight study'):
        protocol = sim.simulate_protocol(truth, seed=seed)
        positions = sim.positions_for_calibration(protocol)
        res = calibrate_boresight(positions, None if args.no_prior else sim.nominal_mount(),
                                  weighting=args.weighting)
        errs.append(rotation_angle_deg(res.rotation, truth))
        means.append(res.mean_error_deg)
        print(f'seed {seed}: rotation error {errs[-1]:.4f} deg, mean per-position '
              f'{means[-1]:.4f} deg, rpy 1-sigma {np.round(res.rpy_std_deg, 4).tolist()}')
    print(f'boresight error over {args.trials} trials: mean {np.mean(errs):.4f} deg, max '
          f'{np.max(errs):.4f} deg (target < 0.05 deg; paper B: 0.3 deg mean per position)')
    return 0
