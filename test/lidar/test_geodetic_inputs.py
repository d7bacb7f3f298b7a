"""
Geodetic georeferencing inputs: INS bags (NavSatFix + Imu/Odometry) and the one-line errors.

Bad trajectories (latitude/longitude out of range, NaN fixes, time going backwards), an
unknown CRS, a zone crossing (a warning: the first zone's CRS is kept), a scan without
per-point time: each is one line on stderr, exit status 1 (0 for the warning), and no
output file appears.
"""
from accelcal_ros.cli import main
from accelcal_ros.fileio import write_text_atomic
from accelcal_ros.lidar.cloud import make_cloud
from accelcal_ros.lidar.geo_sim import simulate_drive, write_drive_bag
from accelcal_ros.lidar.geodesy import MapProjection
from accelcal_ros.lidar.las import adjusted_gps_to_unix
from accelcal_ros.lidar.pcd import write_pcd
from accelcal_ros.textformats import dump_yaml
import laspy
import numpy as np
import pytest

TOL_M = 0.01
HEADER = 't,lat,lon,h,roll,pitch,yaw'


@pytest.fixture(scope='module')
def drive():
    """Simulate 10 s of driving with 150 targets."""
    return simulate_drive(duration_s=10.0, targets=150, seed=7)


@pytest.fixture(scope='module')
def boresight_file(drive, tmp_path_factory):
    """Write the boresight of the drive as a YAML file."""
    path = tmp_path_factory.mktemp('bs') / 'bs.yaml'
    write_text_atomic(path, dump_yaml({'R': drive.boresight.reshape(-1).tolist()}))
    return path


def _check_bag_output(drive, out, expected_missing=0):
    las = laspy.read(out)
    t = adjusted_gps_to_unix(las.gps_time)
    index = np.searchsorted(drive.cloud['timestamp'], t - 1e-6)
    assert np.abs(drive.cloud['timestamp'][index] - t).max() < 1e-6
    truth = MapProjection('EPSG:32637').from_geodetic(drive.target_lat_deg,
                                                      drive.target_lon_deg, drive.target_h_m)
    got = np.stack([las.x, las.y, las.z], axis=1)
    assert np.linalg.norm(got - truth[index], axis=1).max() < TOL_M
    assert len(las.x) == len(drive.cloud) - expected_missing


@pytest.mark.parametrize('orientation', ['odom', 'imu'])
def test_ins_bag_navsat_with_orientation(drive, boresight_file, tmp_path, capsys,
                                         orientation):
    """Navsat fixes + Odometry or Imu orientation: targets within 1 cm; NO_FIX counted."""
    bag = write_drive_bag(tmp_path / f'ins_{orientation}', 'mcap', drive,
                          orientation=orientation, no_fix=range(300, 340))
    out = tmp_path / 'bag.laz'
    args = ['georeference', str(bag), '--navsat', '/gnss/fix', '--boresight',
            str(boresight_file), '--lever-arm', *[str(v) for v in drive.lever_arm_m],
            '--max-gap-s', '0.05', '-o', str(out)]
    args += ['--imu', '/ins/imu'] if orientation == 'imu' else ['--odom', '/ins/odom']
    assert main(args) == 0
    captured = capsys.readouterr()
    assert '40 fixes with status NO_FIX dropped' in captured.err
    t = drive.cloud['timestamp'] - drive.trajectory.t[0]
    in_hole = int(((t > 2.99) & (t < 3.40)).sum())
    assert f'{in_hole} in gaps' in captured.out
    _check_bag_output(drive, out, in_hole)


def test_ins_bag_errors(drive, boresight_file, tmp_path, capsys):
    """A NaN fix that claims a fix, and an Imu without orientation: one line each."""
    bag = write_drive_bag(tmp_path / 'plain', 'mcap', drive, orientation='odom')
    base = ['georeference', str(bag), '--boresight', str(boresight_file), '-o',
            str(tmp_path / 'x.laz')]
    assert main(base + ['--navsat', '/gnss/fix']) == 0
    capsys.readouterr()
    imu_bag = tmp_path / 'noorient'
    from accelcal_ros.recording.writer import BagWriter

    traj = drive.trajectory
    with BagWriter(imu_bag, 'mcap') as writer:
        writer.add_topic('/fix', 'sensor_msgs/NavSatFix')
        writer.add_topic('/imu', 'sensor_msgs/Imu')
        writer.add_topic('/points', 'sensor_msgs/PointCloud2')
        types = writer.typestore.types
        for k in range(5):
            ns = int(traj.t[k] * 1e9)
            lat = np.nan if k == 3 else traj.lat_deg[k]
            writer.write('/fix', ns, types['sensor_msgs/msg/NavSatFix'](
                header=writer.header(ns, 'gnss'),
                status=types['sensor_msgs/msg/NavSatStatus'](status=0, service=1),
                latitude=float(lat), longitude=float(traj.lon_deg[k]),
                altitude=float(traj.h_m[k]), position_covariance=np.zeros(9),
                position_covariance_type=0))
            writer.write('/imu', ns, writer.imu_message(ns, [0, 0, 9.8], 'imu'))
    base = ['georeference', str(imu_bag), '--boresight', str(boresight_file), '-o',
            str(tmp_path / 'y.laz'), '--navsat', '/fix']
    assert main(base) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'message 3' in err and 'NaN' in err
    assert not (tmp_path / 'y.laz').exists()


def _trajectory(path, rows):
    lines = [HEADER] + [','.join(str(v) for v in r) for r in rows]
    write_text_atomic(path, '\n'.join(lines) + '\n')


@pytest.fixture()
def scan(tmp_path):
    """Three points with absolute per-point times inside [100, 101] s."""
    path = tmp_path / 'scan.pcd'
    write_pcd(path, make_cloud(np.array([[5.0, 0, 0], [0, 5.0, 0], [0, 0, -2.0]]),
                               time=[100.2, 100.5, 100.8], time_field='timestamp',
                               double=True))
    return path


GOOD = [(100.0, 55.75, 37.6, 150.0, 0, 0, 0), (101.0, 55.7501, 37.6001, 150.0, 0, 0, 10)]


@pytest.mark.parametrize('rows, expected', [
    ([(100.0, 95.0, 37.6, 150.0, 0, 0, 0), GOOD[1]], 'latitude 95 deg is outside'),
    ([GOOD[0], (101.0, 55.75, 200.0, 150.0, 0, 0, 0)], 'longitude 200 deg is outside'),
    ([GOOD[0], (101.0, 'nan', 37.6, 150.0, 0, 0, 0)], 'NaN'),
    ([GOOD[1], GOOD[0]], 'time goes backwards'),
    ([GOOD[0], (101.0, 55.7501, 37.6001, 150.0, 0, 0, 1e308)],   # was read: any orientation
     'roll, pitch or yaw beyond +-100000 deg'),
])
def test_bad_trajectory_is_one_line(tmp_path, capsys, scan, boresight_file, rows, expected):
    """Each bad trajectory: exit 1, one line naming the file and line, no output."""
    _trajectory(tmp_path / 'traj.csv', rows)
    out = tmp_path / 'out.laz'
    assert main(['georeference', '--cloud', str(scan), '--trajectory',
                 str(tmp_path / 'traj.csv'), '--boresight', str(boresight_file), '-o',
                 str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and expected in err and 'traj.csv:' in err
    assert not out.exists()


@pytest.mark.parametrize('crs, expected', [('EPSG:999999', 'unknown CRS'),
                                           ('not-a-crs', 'unknown CRS'),
                                           ('EPSG:4326', 'not a projected CRS'),
                                           ('EPSG:5773', 'not a projected CRS'),
                                           # EGM96 in the file, ellipsoidal h in the points
                                           ('EPSG:32637+5773', 'has a vertical part'),
                                           ('EPSG:32637+5773', 'give EPSG:32637')])
def test_bad_crs_is_one_line(tmp_path, capsys, scan, boresight_file, crs, expected):
    """An unknown or geographic CRS: one line, exit 1."""
    _trajectory(tmp_path / 'traj.csv', GOOD)
    assert main(['georeference', '--cloud', str(scan), '--trajectory',
                 str(tmp_path / 'traj.csv'), '--boresight', str(boresight_file),
                 '--crs', crs, '-o', str(tmp_path / 'o.laz')]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and expected in err


def test_a_crs_whose_area_of_use_misses_the_survey_is_warned(
        tmp_path, capsys, scan, boresight_file):
    """--crs EPSG:32601 (UTM 1N) for Moscow was written without a word (scale 1.055)."""
    _trajectory(tmp_path / 'traj.csv', GOOD)
    for crs, warned in (('EPSG:32601', True), ('EPSG:32637', False), ('EPSG:3857', False)):
        out = tmp_path / f'{crs[5:]}.laz'
        assert main(['georeference', '--cloud', str(scan), '--trajectory',
                     str(tmp_path / 'traj.csv'), '--boresight', str(boresight_file),
                     '--crs', crs, '-o', str(out)]) == 0
        warnings = [line for line in capsys.readouterr().err.splitlines()
                    if 'area of use' in line]
        assert len(warnings) == int(warned), warnings
        if warned:
            assert 'lon -180..-174' in warnings[0] and '2 of 2 fixes' in warnings[0]
            assert 'distorted or invalid' in warnings[0]
        assert laspy.read(out).header.parse_crs().to_epsg() == int(crs[5:])


def test_zone_crossing_keeps_the_first_zone(tmp_path, capsys, scan, boresight_file):
    """A trajectory from zone 36 into 37: one warning line, the cloud stays in 36N."""
    _trajectory(tmp_path / 'traj.csv', [(100.0, 55.75, 35.9995, 150.0, 0, 0, 0),
                                        (101.0, 55.75, 36.0005, 150.0, 0, 0, 0)])
    out = tmp_path / 'o.laz'
    assert main(['georeference', '--cloud', str(scan), '--trajectory',
                 str(tmp_path / 'traj.csv'), '--boresight', str(boresight_file),
                 '-o', str(out)]) == 0
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if 'EPSG:32637' in line]
    assert len(lines) == 1 and 'EPSG:32636' in lines[0] and 'stays' in lines[0]
    assert laspy.read(out).header.parse_crs().to_epsg() == 32636


def test_cloud_without_time_and_las_without_crs(tmp_path, capsys, boresight_file):
    """A scan without per-point time; LAS output from local poses: one line each."""
    _trajectory(tmp_path / 'traj.csv', GOOD)
    path = tmp_path / 'notime.pcd'
    write_pcd(path, make_cloud(np.ones((3, 3))))
    assert main(['georeference', '--cloud', str(path), '--trajectory',
                 str(tmp_path / 'traj.csv'), '--boresight', str(boresight_file),
                 '-o', str(tmp_path / 'o.laz')]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'no per-point time' in err
    write_text_atomic(tmp_path / 'poses.csv', 't,x,y,z,qx,qy,qz,qw\n0,0,0,0,0,0,0,1\n'
                                              '1,1,0,0,0,0,0,1\n')
    assert main(['georeference', '--cloud', str(path), '--poses', str(tmp_path / 'poses.csv'),
                 '--boresight', str(boresight_file), '-o', str(tmp_path / 'o.las')]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'needs a geodetic trajectory' in err


def test_sample_files_run_the_readme_commands(tmp_path, monkeypatch, capsys):
    """write_sample's files run the README's georeference lines as printed."""
    from accelcal_ros.lidar.geo_sim import write_sample

    names = write_sample(tmp_path, seconds=4.0)
    assert all((tmp_path / n).exists() for n in names)
    monkeypatch.chdir(tmp_path)
    lever = ['--lever-arm', '0.4', '-0.1', '0.3']
    assert main(['georeference', '--cloud', 'drive_scan.pcd', '--trajectory',
                 'drive_trajectory.csv', '--boresight', 'drive_boresight.yaml', *lever,
                 '-o', 'drive_utm.laz']) == 0
    assert main(['georeference', 'rosbag2_ins', '--points', '/velodyne_points', '--navsat',
                 '/gnss/fix', '--odom', '/ins/odom', '--boresight', 'drive_boresight.yaml',
                 *lever, '-o', 'ins_utm.laz']) == 0
    first, second = laspy.read('drive_utm.laz'), laspy.read('ins_utm.laz')
    assert first.header.parse_crs().to_epsg() == second.header.parse_crs().to_epsg() == 32637
    assert 0 < len(second.x) <= len(first.x)
    assert 'NO_FIX dropped' in capsys.readouterr().err


@pytest.mark.parametrize('extra', [['--crs', 'EPSG:32637'], ['--crs', 'garbage'],
                                   ['--imu', '/imu/data']])
def test_geodetic_options_with_local_poses_are_refused(tmp_path, capsys, boresight_file,
                                                       extra):
    """--crs (or --imu) with --poses would be ignored: one line naming it, nothing written."""
    write_pcd(tmp_path / 'scan.pcd', make_cloud(np.ones((3, 3)), time=np.zeros(3)))
    write_text_atomic(tmp_path / 'poses.csv', 't,x,y,z,qx,qy,qz,qw\n0,0,0,0,0,0,0,1\n'
                                              '1,1,0,0,0,0,0,1\n')
    out = tmp_path / 'o.pcd'
    assert main(['georeference', '--cloud', str(tmp_path / 'scan.pcd'), '--poses',
                 str(tmp_path / 'poses.csv'), '--boresight', str(boresight_file), *extra,
                 '-o', str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and extra[0] in err and 'geodetic trajectory' in err
    assert not out.exists()


@pytest.mark.parametrize('extra, out_name, words', [
    (['--heading', 'ned'], 'o.ply', '--heading is the convention of the --trajectory'),
    (['--points', '/velodyne_points'], 'o.ply', '--points names a topic of a BAG'),
    (['--odom', '/odom', '--points', '/p'], 'o.ply', '--points and --odom name a topic'),
    (['--data', 'binary_compressed'], 'o.ply', 'binary_compressed is a PCD encoding'),
    (['BAG'], 'o.ply', 'give the scans once'),
])
def test_an_option_the_inputs_would_ignore_is_refused(tmp_path, capsys, boresight_file,
                                                      extra, out_name, words):
    """Each was silently ignored (--heading ned on local poses, a BAG beside --cloud...)."""
    write_pcd(tmp_path / 'scan.pcd', make_cloud(np.ones((3, 3)), time=np.zeros(3)))
    write_text_atomic(tmp_path / 'poses.csv', 't,x,y,z,qx,qy,qz,qw\n0,0,0,0,0,0,0,1\n'
                                              '1,1,0,0,0,0,0,1\n')
    extra = [str(tmp_path) if e == 'BAG' else e for e in extra]
    out = tmp_path / out_name
    assert main(['georeference', '--cloud', str(tmp_path / 'scan.pcd'), '--poses',
                 str(tmp_path / 'poses.csv'), '--boresight', str(boresight_file), *extra,
                 '-o', str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and words in err, err
    assert not out.exists()


def test_data_encoding_for_las_is_refused(tmp_path, capsys, scan, boresight_file):
    """--data ascii -o x.laz wrote a binary LAZ without a word; --heading goes with it fine."""
    _trajectory(tmp_path / 'traj.csv', GOOD)
    args = ['georeference', '--cloud', str(scan), '--trajectory', str(tmp_path / 'traj.csv'),
            '--boresight', str(boresight_file), '--heading', 'enu']
    assert main(args + ['--data', 'ascii', '-o', str(tmp_path / 'o.laz')]) == 1
    assert 'LAS/LAZ, which has one' in capsys.readouterr().err
    assert not (tmp_path / 'o.laz').exists()
    assert main(args + ['--data', 'ascii', '-o', str(tmp_path / 'o.ply')]) == 0
    assert (tmp_path / 'o.ply').read_bytes().startswith(b'ply\nformat ascii')
