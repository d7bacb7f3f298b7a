"""
Simulated GNSS/INS drive with surveyed targets: the ground truth of geodetic georeferencing.

The platform drives a smooth curve (about ``speed_m_s``, turning, with roll/pitch
wobble and a heading that follows the path) around a place given in WGS84 (default
55.75 N, 37.6 E: UTM 37N, 1.4 deg west of the central meridian, convergence
-1.16 deg, scale factor 0.99970). The body pose is exact at every instant: position in
the ENU frame of the start point, carried to ECEF and geodetic; attitude REP-103 body in
the ENU frame of the *current* position. Targets are placed at known geodetic
coordinates (5..``max_range_m`` m from the scanner when it sees them, -2..+8 m height)
and each is observed once by the scanner at a random time: its LiDAR-frame point is
``p_L = R^T (C_E(t)^T (X - r(t)) - l)``, noise-free. A VLP-16-like ring and intensity
come with it. Times are Unix seconds (``t0_unix_s``), the ROS clock of a recording.
"""
from dataclasses import dataclass
from typing import Any, List, Optional, Sequence, Tuple

from accelcal_ros.frames import rotation_from_rpy_radians
from accelcal_ros.lidar.cloud import make_cloud
from accelcal_ros.lidar.geodesy import ecef_from_enu, enu_from_body_rpy, geodetic_to_ecef
from accelcal_ros.lidar.geotraj import GeodeticTrajectory
import numpy as np


@dataclass
class GeoDrive:
    """A simulated drive: trajectory samples, the scan of targets and their truth."""

    trajectory: GeodeticTrajectory
    cloud: np.ndarray
    target_lat_deg: np.ndarray
    target_lon_deg: np.ndarray
    target_h_m: np.ndarray
    boresight: np.ndarray
    lever_arm_m: np.ndarray
    speed_m_s: float = 12.0


def _ecef_to_geodetic(xyz: np.ndarray) -> np.ndarray:
    from pyproj import Transformer

    tr = Transformer.from_crs('EPSG:4978', 'EPSG:4979', always_xy=True)
    lon, lat, h = tr.transform(xyz[:, 0], xyz[:, 1], xyz[:, 2])
    return np.stack([lat, lon, h], axis=1)


class DriveTruth:
    """The exact body pose of the simulated drive at any time (s after the start)."""

    def __init__(self, lat0_deg: float, lon0_deg: float, h0_m: float, speed_m_s: float) -> None:
        self.lat0, self.lon0, self.h0 = np.radians(lat0_deg), np.radians(lon0_deg), h0_m
        self.speed = speed_m_s
        self.origin = geodetic_to_ecef(self.lat0, self.lon0, h0_m)[0]
        self.rot0 = ecef_from_enu(self.lat0, self.lon0)[0]

    @staticmethod
    def heading(t: np.ndarray) -> np.ndarray:
        """Return the direction of travel (rad from east, counter-clockwise)."""
        return 0.4 + 0.02 * t + 0.15 * np.sin(0.1 * t)

    def enu(self, t: np.ndarray) -> np.ndarray:
        """Return the body position (N, 3) in the start point's ENU frame (m)."""
        step = 0.001
        grid = np.arange(0.0, float(np.max(t)) + 2 * step, step)
        hg = self.heading(grid)
        east = np.concatenate([[0.0], np.cumsum(np.cos(hg[:-1]) * self.speed * step)])
        north = np.concatenate([[0.0], np.cumsum(np.sin(hg[:-1]) * self.speed * step)])
        return np.stack([np.interp(t, grid, east), np.interp(t, grid, north),
                         0.3 * np.sin(0.2 * t)], axis=1)

    def pose(self, t: np.ndarray) -> Tuple[np.ndarray, ...]:
        """Return ``(lat_deg, lon_deg, h_m, C_enu_body (N,3,3), r_ecef (N,3), C_ecef_body)``."""
        t = np.asarray(t, dtype=float).reshape(-1)
        p = self.enu(t)
        ecef = self.origin + p @ self.rot0.T
        geo = _ecef_to_geodetic(ecef)
        yaw = self.heading(t) + 0.02 * np.sin(1.3 * t)
        roll = 0.03 * np.sin(0.9 * t)
        pitch = 0.02 * np.cos(0.7 * t)
        c_enu = enu_from_body_rpy(roll, pitch, yaw)
        lat, lon = np.radians(geo[:, 0]), np.radians(geo[:, 1])
        c_ecef = np.einsum('nij,njk->nik', ecef_from_enu(lat, lon), c_enu)
        return geo[:, 0], geo[:, 1], geo[:, 2], c_enu, ecef, c_ecef


def simulate_drive(lat0_deg: float = 55.75, lon0_deg: float = 37.6, h0_m: float = 150.0,
                   duration_s: float = 30.0, speed_m_s: float = 12.0, rate_hz: float = 100.0,
                   targets: int = 400, max_range_m: float = 100.0, seed: int = 0,
                   t0_unix_s: float = 1.7e9,
                   lever_arm_m: Sequence[float] = (0.4, -0.1, 0.3)) -> GeoDrive:
    """Simulate a drive and its targets (see the module docstring)."""
    rng = np.random.default_rng(seed)
    truth = DriveTruth(lat0_deg, lon0_deg, h0_m, speed_m_s)
    ts = np.arange(0.0, duration_s + 0.5 / rate_hz, 1.0 / rate_hz)
    lat, lon, h, c_enu, _, _ = truth.pose(ts)
    traj = GeodeticTrajectory(t0_unix_s + ts, lat, lon, h, c_enu)
    boresight = rotation_from_rpy_radians(*np.radians([1.5, -44.0, 2.5]))
    lever = np.asarray(lever_arm_m, dtype=float)
    t_obs = np.sort(rng.uniform(0.0, duration_s, targets))
    _, _, _, c_enu_o, r_o, c_o = truth.pose(t_obs)
    rng_m = rng.uniform(5.0, max_range_m, targets)
    az = rng.uniform(0.0, 2 * np.pi, targets)
    up = rng.uniform(-2.0, 8.0, targets)
    horiz = np.sqrt(np.maximum(rng_m ** 2 - up ** 2, 1.0))
    offset_enu = np.stack([horiz * np.cos(az), horiz * np.sin(az), up], axis=1)
    lat_o = np.radians(_ecef_to_geodetic(r_o)[:, 0])
    lon_o = np.radians(_ecef_to_geodetic(r_o)[:, 1])
    target_ecef = r_o + np.einsum('nij,nj->ni', ecef_from_enu(lat_o, lon_o), offset_enu)
    geo = _ecef_to_geodetic(target_ecef)
    target_ecef = geodetic_to_ecef(np.radians(geo[:, 0]), np.radians(geo[:, 1]), geo[:, 2])
    body = np.einsum('nji,nj->ni', c_o, target_ecef - r_o)
    p_lidar = (body - lever) @ boresight
    cloud = make_cloud(p_lidar, rng.uniform(1, 255, targets), rng.integers(0, 16, targets),
                       t0_unix_s + t_obs, 'timestamp')
    return GeoDrive(traj, cloud, geo[:, 0], geo[:, 1], geo[:, 2], boresight, lever, speed_m_s)


def vlp16_scans(drive: GeoDrive, revolutions: int, range_m: float = 20.0,
                seed: int = 0) -> np.ndarray:
    """Return a VLP-16-like cloud (``timestamp`` absolute) over the drive, for throughput."""
    from accelcal_ros.lidar.scanner_sim import Vlp16

    dirs, ring, times = Vlp16().beams(revolutions)
    rng = np.random.default_rng(seed)
    pts = dirs * (range_m + rng.uniform(-5.0, 5.0, len(dirs)))[:, None]
    t0 = float(drive.trajectory.t[0])
    return make_cloud(pts, rng.uniform(0, 255, len(dirs)), ring, t0 + 0.05 + times,
                      'timestamp')


def write_drive_bag(path: Any, fmt: str, drive: GeoDrive, cloud: Optional[np.ndarray] = None,
                    orientation: str = 'odom', no_fix: Sequence[int] = (),
                    scan_s: float = 0.1) -> Any:
    """
    Write a drive as an INS recording: NavSatFix, Imu or Odometry orientation, PointCloud2.

    Fixes of index ``no_fix`` get status NO_FIX (and NaN coordinates, as receivers send);
    the scans are ``cloud`` (default the targets) cut every ``scan_s`` with a relative
    float32 ``time`` field (velodyne_pointcloud's layout).
    """
    from accelcal_ros.recording.writer import BagWriter, sensor_data_qos
    from scipy.spatial.transform import Rotation

    cloud = drive.cloud if cloud is None else cloud
    traj = drive.trajectory
    quats = Rotation.from_matrix(traj.enu_from_body).as_quat()
    bad = {int(k) for k in no_fix}
    with BagWriter(path, fmt) as writer:
        types = writer.typestore.types
        writer.add_topic('/gnss/fix', 'sensor_msgs/NavSatFix')
        o_topic = '/ins/imu' if orientation == 'imu' else '/ins/odom'
        writer.add_topic(o_topic, 'sensor_msgs/Imu' if orientation == 'imu'
                         else 'nav_msgs/Odometry')
        writer.add_topic('/velodyne_points', 'sensor_msgs/PointCloud2', [sensor_data_qos()])
        events = []
        for k, t in enumerate(traj.t):
            ns = int(round(t * 1e9))
            status = -1 if k in bad else 0
            lat, lon, h = ((np.nan, np.nan, np.nan) if k in bad else
                           (traj.lat_deg[k], traj.lon_deg[k], traj.h_m[k]))
            fix = types['sensor_msgs/msg/NavSatFix'](
                header=writer.header(ns, 'gnss', '/gnss/fix'),
                status=types['sensor_msgs/msg/NavSatStatus'](status=status, service=1),
                latitude=float(lat), longitude=float(lon), altitude=float(h),
                position_covariance=np.zeros(9), position_covariance_type=0)
            events.append((ns, '/gnss/fix', fix))
            q = quats[k]
            if orientation == 'imu':
                msg = writer.imu_message(ns, [0.0, 0.0, 9.81], 'imu_link', topic=o_topic)
                msg.orientation = types['geometry_msgs/msg/Quaternion'](
                    x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))
                msg.orientation_covariance = np.zeros(9)
            else:
                msg = writer.odometry_message(ns, [0.0, 0.0, 0.0], q, 'enu', 'base_link',
                                              topic=o_topic)
            events.append((ns, o_topic, msg))
        t = cloud['timestamp']
        edges = np.arange(float(t.min()), float(t.max()) + scan_s, scan_s)
        index = np.searchsorted(t, edges)
        order_ok = np.all(np.diff(t) >= 0)
        if not order_ok:
            raise ValueError('cloud times must be sorted')
        for a, b, start in zip(index[:-1], index[1:], edges[:-1]):
            if b <= a:
                continue
            part = cloud[a:b]
            scan = make_cloud(np.stack([part['x'], part['y'], part['z']], axis=1),
                              part['intensity'], part['ring'], part['timestamp'] - start)
            ns = int(round(start * 1e9))
            events.append((ns, '/velodyne_points', writer.pointcloud2_message(
                ns, scan, 'velodyne', topic='/velodyne_points')))
        for ns, topic, msg in sorted(events, key=lambda e: e[0]):
            writer.write(topic, ns, msg)
    return path


def flat_shortcut(drive: GeoDrive, with_convergence: bool, with_scale: bool) -> np.ndarray:
    """
    Return the targets placed by the flat shortcut: UTM of the pose + the ENU offset.

    The offset is rotated by the meridian convergence and scaled by the point scale factor
    at the pose only when asked (both from PROJ): what georeferencing without an exact
    projection would give. Exact poses, so only the projection shortcut differs.
    """
    from accelcal_ros.lidar.cloud import xyz

    traj = drive.trajectory
    truth = DriveTruth(float(traj.lat_deg[0]), float(traj.lon_deg[0]), float(traj.h_m[0]),
                       drive.speed_m_s)
    lat, lon, h, c_enu, _, _ = truth.pose(drive.cloud['timestamp'] - traj.t[0])
    proj = traj.projection()
    origin = proj.from_geodetic(lat, lon, h)
    offset = np.einsum('nij,nj->ni', c_enu, xyz(drive.cloud) @ drive.boresight.T
                       + drive.lever_arm_m)
    factors = [proj.factors(float(a), float(b)) for a, b in zip(lat, lon)]
    gamma = np.radians([f.convergence_deg for f in factors]) if with_convergence \
        else np.zeros(len(lat))
    k = np.array([f.scale for f in factors]) if with_scale else np.ones(len(lat))
    east = k * (np.cos(gamma) * offset[:, 0] - np.sin(gamma) * offset[:, 1])
    north = k * (np.sin(gamma) * offset[:, 0] + np.cos(gamma) * offset[:, 1])
    return origin + np.stack([east, north, offset[:, 2]], axis=1)


def target_truth(drive: GeoDrive) -> np.ndarray:
    """Return the targets' true map coordinates (PROJ straight from their geodetic truth)."""
    return drive.trajectory.projection().from_geodetic(drive.target_lat_deg,
                                                       drive.target_lon_deg, drive.target_h_m)


def write_sample(directory: Any, seconds: float = 10.0) -> List[str]:
    """
    Write the README's georeferencing inputs into ``directory``; return the names.

    ``drive_trajectory.csv`` (t,lat,lon,h,roll,pitch,yaw, ENU form), ``drive_scan.pcd``
    (the targets plus two VLP-16 revolutions, absolute ``timestamp``),
    ``drive_boresight.yaml`` and ``rosbag2_ins`` (mcap: /gnss/fix NavSatFix, /ins/odom
    Odometry orientation, /velodyne_points). Lever arm 0.4 -0.1 0.3 m.
    """
    import os

    from accelcal_ros.fileio import write_text_atomic
    from accelcal_ros.textformats import dump_yaml
    from accelcal_ros.lidar.geotraj import write_trajectory_csv
    from accelcal_ros.lidar.pcd import write_pcd

    drive = simulate_drive(duration_s=seconds, targets=200, seed=1)
    os.makedirs(directory, exist_ok=True)
    write_trajectory_csv(os.path.join(directory, 'drive_trajectory.csv'), drive.trajectory)
    scans = vlp16_scans(drive, 2)
    merged = np.concatenate([drive.cloud, scans])
    merged = merged[np.argsort(merged['timestamp'], kind='stable')]
    write_pcd(os.path.join(directory, 'drive_scan.pcd'), merged)
    write_text_atomic(os.path.join(directory, 'drive_boresight.yaml'),
                      dump_yaml({'R': drive.boresight.reshape(-1).tolist()}))
    write_drive_bag(os.path.join(directory, 'rosbag2_ins'), 'mcap', drive, cloud=merged,
                    no_fix=range(200, 210))
    return ['drive_trajectory.csv', 'drive_scan.pcd', 'drive_boresight.yaml', 'rosbag2_ins']
