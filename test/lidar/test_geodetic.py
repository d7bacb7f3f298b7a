"""
Georeferencing into UTM against ground truth: a simulated drive at 55.75 N 37.6 E.

The targets sit at known WGS84 coordinates; their true UTM 37N coordinates come from
pyproj straight from the geodetic truth. ``accelcal georeference`` must put every one
within 1 cm, and the LAS/LAZ it writes must read back (laspy) with the CRS, the
coordinates to 1 mm and the GPS times. Dropping the meridian convergence (1.16 deg here)
or the scale factor (0.99970) must fail the same 1 cm test.
"""
from accelcal_ros.cli import main
from accelcal_ros.fileio import write_text_atomic
from accelcal_ros.lidar.cloud import xyz
from accelcal_ros.lidar.geo_sim import flat_shortcut, simulate_drive, target_truth
from accelcal_ros.lidar.geodesy import enu_from_body_rpy, MapProjection, utm_epsg
from accelcal_ros.lidar.geotraj import (GeodeticTrajectory, MapGeoreferencer,
                                        write_trajectory_csv)
from accelcal_ros.lidar.las import unix_to_adjusted_gps
from accelcal_ros.lidar.pcd import write_pcd
from accelcal_ros.textformats import dump_yaml
import laspy
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

TOL_M = 0.01


@pytest.fixture(scope='module')
def drive():
    """Simulate 30 s of driving at 12 m/s with 400 targets 5..100 m away."""
    return simulate_drive()


@pytest.fixture(scope='module')
def files(drive, tmp_path_factory):
    """Write the inputs of the command: trajectory CSV, targets PCD, boresight YAML."""
    d = tmp_path_factory.mktemp('drive')
    write_trajectory_csv(str(d / 'traj.csv'), drive.trajectory)
    write_pcd(d / 'targets.pcd', drive.cloud)
    write_text_atomic(d / 'bs.yaml', dump_yaml({'R': drive.boresight.reshape(-1).tolist()}))
    return d


def _truth(drive, crs='EPSG:32637'):
    return MapProjection(crs).from_geodetic(drive.target_lat_deg, drive.target_lon_deg,
                                            drive.target_h_m)


def _lever(drive):
    return [str(v) for v in drive.lever_arm_m]


def test_utm_zone_and_factors_of_the_place():
    """55.75 N 37.6 E is UTM 37N; convergence about -1.16 deg, scale 0.99970 (PROJ)."""
    assert utm_epsg(55.75, 37.6) == 32637
    assert utm_epsg(-33.9, 18.4) == 32734
    assert utm_epsg(60.0, 5.0) == 32632        # Norway exception
    f = MapProjection('EPSG:32637').factors(55.75, 37.6)
    assert -1.3 < f.convergence_deg < -1.0 and abs(f.scale - 0.99970) < 5e-5


def test_targets_land_within_1cm_of_their_true_utm(drive):
    """Core path: every target within 1 cm (noise-free; the residual is interpolation)."""
    geo = MapGeoreferencer(drive.trajectory, drive.boresight, drive.lever_arm_m)
    out, keep, stats = geo.georeference(xyz(drive.cloud), drive.cloud['timestamp'])
    assert keep.all() and stats.kept == len(drive.cloud)
    err = np.linalg.norm(out - _truth(drive), axis=1)
    assert err.max() < TOL_M


def test_dropping_convergence_or_scale_would_fail(drive):
    """The targets placed with a flat ENU -> UTM shortcut miss by more than 1 cm."""
    true_utm = _truth(drive)
    errors = {case: np.linalg.norm(flat_shortcut(drive, *case) - true_utm, axis=1).max()
              for case in ((False, False), (True, False), (False, True), (True, True))}
    assert errors[(False, False)] > 100 * TOL_M       # 1.16 deg at 100 m: ~2 m
    assert errors[(False, True)] > 100 * TOL_M
    assert errors[(True, False)] > 2 * TOL_M          # 3e-4 at 100 m: ~3 cm
    assert errors[(True, True)] < TOL_M               # the shortcut with both is close
    assert np.array_equal(target_truth(drive), true_utm)


def test_study_georeference_prints_the_table(capsys):
    """``accelcal study georeference``: exact path sub-millimetre, shortcuts metres."""
    assert main(['study', 'georeference']) == 0
    text = capsys.readouterr().out
    exact = float(text.split('exact (ENU of the pose -> ECEF -> PROJ)')[1].split()[0])
    assert exact < 1.0
    assert 'flat: no convergence' in text


def test_cli_writes_laz_that_reads_back(drive, files, tmp_path, capsys):
    """LAZ: CRS EPSG:32637 as WKT, 1 mm coordinates, adjusted GPS times, ring, intensity."""
    out = tmp_path / 'cloud.laz'
    assert main(['georeference', '--cloud', str(files / 'targets.pcd'), '--trajectory',
                 str(files / 'traj.csv'), '--boresight', str(files / 'bs.yaml'),
                 '--lever-arm', *_lever(drive), '-o', str(out)]) == 0
    text = capsys.readouterr().out
    assert 'EPSG:32637' in text and 'convergence' in text and 'Adjusted Standard GPS' in text
    las = laspy.read(out)
    header = las.header
    assert header.version.major == 1 and header.version.minor == 4
    assert header.global_encoding.wkt and header.parse_crs().to_epsg() == 32637
    assert any(b'ellipsoidal' in v.record_data for v in header.vlrs
               if hasattr(v, 'record_data'))
    got = np.stack([las.x, las.y, las.z], axis=1)
    truth = _truth(drive)
    assert np.abs(got - truth).max() < TOL_M
    geo = MapGeoreferencer(drive.trajectory, drive.boresight, drive.lever_arm_m)
    core, _, _ = geo.georeference(xyz(drive.cloud), drive.cloud['timestamp'])
    assert np.abs(got - core).max() <= 0.0005 + 1e-9           # 1 mm steps
    assert np.array_equal(las.gps_time, unix_to_adjusted_gps(drive.cloud['timestamp']))
    # 1.7e9 Unix s (2023-11-14) is GPS 1384035218 s (18 leap seconds): adjusted - 1e9
    assert unix_to_adjusted_gps(1.7e9) == pytest.approx(384035218.0, abs=1e-6)
    assert np.array_equal(las.ring, drive.cloud['ring'])
    assert np.array_equal(las.intensity, np.round(drive.cloud['intensity']).astype(int))
    assert np.all(las.return_number == 1)


def test_cli_las_and_ply_agree_and_crs_option(drive, files, tmp_path):
    """.las (uncompressed) and .ply (float64) hold the same points; --crs another zone."""
    from accelcal_ros.lidar.ply import read_ply

    base = ['georeference', '--cloud', str(files / 'targets.pcd'), '--trajectory',
            str(files / 'traj.csv'), '--boresight', str(files / 'bs.yaml'),
            '--lever-arm', *_lever(drive)]
    assert main(base + ['-o', str(tmp_path / 'a.las')]) == 0
    assert main(base + ['-o', str(tmp_path / 'a.ply')]) == 0
    las = laspy.read(tmp_path / 'a.las')
    ply = read_ply(tmp_path / 'a.ply')
    assert np.abs(las.x - ply['x']).max() <= 0.0005 + 1e-9
    assert np.abs(ply['y'] - _truth(drive)[:, 1]).max() < TOL_M
    assert main(base + ['--crs', 'EPSG:32638', '-o', str(tmp_path / 'b.laz')]) == 0
    other = laspy.read(tmp_path / 'b.laz')
    assert other.header.parse_crs().to_epsg() == 32638
    got = np.stack([other.x, other.y, other.z], axis=1)
    assert np.abs(got - _truth(drive, 'EPSG:32638')).max() < TOL_M


def test_ned_heading_form_gives_the_same_cloud(drive, files, tmp_path):
    """The INS form (roll/pitch/heading of FRD in NED) of the same attitude agrees."""
    traj = drive.trajectory
    c_enu = traj.enu_from_body
    frd = np.diag([1.0, -1.0, -1.0])
    enu_ned = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    c_ned = np.einsum('ij,njk,kl->nil', enu_ned, c_enu, frd)
    ypr = np.degrees(Rotation.from_matrix(c_ned).as_euler('ZYX'))
    back = enu_from_body_rpy(*np.radians([ypr[:, 2], ypr[:, 1], ypr[:, 0]]), heading='ned')
    assert np.abs(back - c_enu).max() < 1e-12
    lines = ['t,lat,lon,h,roll,pitch,yaw']
    rows = zip(traj.t, traj.lat_deg, traj.lon_deg, traj.h_m, ypr[:, 2], ypr[:, 1],
               ypr[:, 0] % 360.0)
    lines += [f'{t:.9f},{a:.12f},{b:.12f},{h:.6f},{r:.10f},{p:.10f},{y:.10f}'
              for t, a, b, h, r, p, y in rows]
    write_text_atomic(tmp_path / 'ned.csv', '\n'.join(lines) + '\n')
    out = tmp_path / 'ned.laz'
    assert main(['georeference', '--cloud', str(files / 'targets.pcd'), '--trajectory',
                 str(tmp_path / 'ned.csv'), '--heading', 'ned', '--boresight',
                 str(files / 'bs.yaml'), '--lever-arm', *_lever(drive), '-o', str(out)]) == 0
    las = laspy.read(out)
    assert np.abs(np.stack([las.x, las.y, las.z], 1) - _truth(drive)).max() < TOL_M


def test_points_outside_or_in_gaps_are_dropped_and_counted(drive):
    """A 2 s hole in the trajectory and a shortened span: dropped, counted, never invented."""
    traj = drive.trajectory
    t = traj.t - traj.t[0]
    keep = ((t < 10.0) | (t > 12.0)) & (t > 2.0) & (t < 28.0)
    cut = GeodeticTrajectory(traj.t[keep], traj.lat_deg[keep], traj.lon_deg[keep],
                             traj.h_m[keep], traj.enu_from_body[keep])
    geo = MapGeoreferencer(cut, drive.boresight, drive.lever_arm_m, max_gap_s=0.5)
    times = drive.cloud['timestamp']
    out, kept, stats = geo.georeference(xyz(drive.cloud), times)
    rel = times - traj.t[0]
    first, last = cut.t[0] - traj.t[0], cut.t[-1] - traj.t[0]
    in_gap = (rel > t[keep][t[keep] < 10.0].max()) & (rel < t[keep][t[keep] > 12.0].min())
    assert stats.before_span == int((rel < first).sum()) > 0
    assert stats.after_span == int((rel > last).sum()) > 0
    assert stats.in_gap == int(in_gap.sum()) > 0
    assert stats.kept == len(out) == len(times) - stats.before_span - stats.after_span \
        - stats.in_gap
    assert not kept[in_gap].any()
    assert np.linalg.norm(out - _truth(drive)[kept], axis=1).max() < TOL_M
    loose = MapGeoreferencer(cut, drive.boresight, drive.lever_arm_m, max_gap_s=5.0)
    assert loose.georeference(xyz(drive.cloud), times)[2].in_gap == 0


def test_southern_hemisphere_uses_the_south_zone(tmp_path):
    """A drive at 33.9 S 18.4 E goes to EPSG:32734 and lands within 1 cm."""
    south = simulate_drive(-33.9, 18.4, 20.0, duration_s=10.0, targets=100, seed=3)
    geo = MapGeoreferencer(south.trajectory, south.boresight, south.lever_arm_m)
    assert geo.projection.crs.to_epsg() == 32734
    out, _, _ = geo.georeference(xyz(south.cloud), south.cloud['timestamp'])
    truth = MapProjection('EPSG:32734').from_geodetic(south.target_lat_deg,
                                                      south.target_lon_deg, south.target_h_m)
    assert np.linalg.norm(out - truth, axis=1).max() < TOL_M


def test_las_writer_streams_in_batches_and_is_atomic(tmp_path):
    """Many small batches read back whole; a failure leaves the old file and no temp."""
    from accelcal_ros.lidar.las import LasCloudWriter

    proj = MapProjection('EPSG:32637')
    rng = np.random.default_rng(2)
    pts = np.array([412000.0, 6179000.0, 150.0]) + rng.uniform(-100, 100, (5000, 3))
    times = 1.7e9 + np.arange(5000) * 1e-4
    path = tmp_path / 'c.laz'
    with LasCloudWriter(path, proj.wkt(), pts[0], True, True, proj.name,
                        flush_points=1000) as writer:
        for a in range(0, 5000, 700):
            writer.write(pts[a:a + 700], times[a:a + 700], ring=(np.arange(5000) % 16)[a:a + 700])
    las = laspy.read(path)
    assert len(las.x) == 5000 and las.header.point_count == 5000
    assert np.abs(np.stack([las.x, las.y, las.z], 1) - pts).max() <= 0.0005 + 1e-9
    assert np.array_equal(las.gps_time, unix_to_adjusted_gps(times))
    assert np.array_equal(las.ring, np.arange(5000) % 16)
    assert np.allclose(las.header.mins, np.round(pts.min(axis=0), 3))
    before = path.read_bytes()
    with pytest.raises(RuntimeError):
        with LasCloudWriter(path, proj.wkt(), pts[0], True, False,
                            flush_points=1000) as writer:
            writer.write(pts, times)
            raise RuntimeError('interrupted')
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ['c.laz']


def test_heading_conventions():
    """ENU yaw 0 faces east (CCW); NED heading 90 (clockwise from north) is the same."""
    east = enu_from_body_rpy(0.0, 0.0, 0.0)[0]
    assert np.allclose(east, np.eye(3))
    north = enu_from_body_rpy(0.0, 0.0, np.pi / 2)[0]
    assert np.allclose(north @ [1, 0, 0], [0, 1, 0]) and np.allclose(north @ [0, 1, 0],
                                                                     [-1, 0, 0])
    assert np.allclose(enu_from_body_rpy(0.0, 0.0, np.pi / 2, 'ned')[0], np.eye(3))
    nose_up_ned = enu_from_body_rpy(0.0, np.radians(10.0), 0.0, 'ned')[0]   # facing north
    assert np.allclose(nose_up_ned @ [1, 0, 0], [0, np.cos(0.1745329), np.sin(0.1745329)])
    right_wing_down = enu_from_body_rpy(np.radians(10.0), 0.0, np.pi / 2, 'ned')[0]
    assert (right_wing_down @ [0, 1, 0])[2] > 0.17         # left wing (body +y) goes up
