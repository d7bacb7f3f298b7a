"""
GNSS/INS trajectories from a bag, and streaming a bag's scans into a map cloud.

:func:`read_geodetic_trajectory`: sensor_msgs/NavSatFix (WGS84 latitude/longitude deg,
ellipsoidal altitude m) gives the positions; the orientation comes from sensor_msgs/Imu
(its ``orientation``, REP-145; an Imu whose ``orientation_covariance[0]`` is -1 carries
none) or nav_msgs/Odometry (``pose.orientation``) -- in both the REP-103 body in the local
ENU frame, as INS drivers publish it (REP-105 geographic frames). The trajectory's poses are
the fixes; each fix gets the orientation slerped to its time (fixes outside the
orientation stream are dropped, counted). Fixes with status NO_FIX are dropped and
counted; a NaN fix that claims a fix is an error, as are impossible coordinates.

:func:`stream_scans`: every PointCloud2 scan of a topic, georeferenced
(:class:`~accelcal_ros.lidar.geotraj.MapGeoreferencer`) and handed to a sink scan by scan,
so memory stays bounded by a scan.
"""
from typing import Callable, Dict, List, Optional, Tuple

from accelcal_ros.errors import InputError
from accelcal_ros.lidar.cloud import point_times, xyz
from accelcal_ros.lidar.geotraj import GeodeticTrajectory, MapGeoreferencer
from accelcal_ros.recording import convert
from accelcal_ros.recording.bag import BagReader
from accelcal_ros.recording.streams import message_time_s, StampLog
import numpy as np


def _orientation_stream(bag: BagReader, imu_topic: Optional[str], odom_topic: Optional[str]
                        ) -> Tuple[str, np.ndarray, np.ndarray]:
    if imu_topic is None and odom_topic is None:
        try:
            name, is_imu = bag.select_topic(None, (convert.IMU,), '--imu'), True
        except InputError:
            name, is_imu = bag.select_topic(None, (convert.ODOMETRY,), '--odom'), False
    elif imu_topic is not None:
        name, is_imu = bag.select_topic(imu_topic, (convert.IMU,), '--imu'), True
    else:
        name, is_imu = bag.select_topic(odom_topic, (convert.ODOMETRY,), '--odom'), False
    quats, log = [], StampLog()
    for message in bag.messages([name], f'reading {name}'):
        if is_imu:
            q = convert.imu_orientation(message.msg)
            if q is None:
                raise InputError(f'{name}: the Imu messages carry no orientation '
                                 '(orientation_covariance[0] = -1): give the INS topic '
                                 'that does, or --odom')
        else:
            q = convert.odometry_pose(message.msg)[1]
        log.add(message)
        quats.append(q)
    if len(quats) < 2:
        raise InputError(f'{name}: {len(quats)} orientation message(s); need at least 2')
    t = log.times_s(bag.stamp)
    q = np.array(quats)
    norms = np.linalg.norm(q, axis=1)
    good = np.isfinite(norms) & (np.abs(norms - 1.0) < 1e-3)
    order = np.argsort(t[good], kind='stable')
    t, q = t[good][order], q[good][order]
    keep = np.concatenate([[True], np.diff(t) > 0])
    return name, t[keep], q[keep]


def read_geodetic_trajectory(bag: BagReader, navsat_topic: Optional[str],
                             imu_topic: Optional[str] = None, odom_topic: Optional[str] = None
                             ) -> GeodeticTrajectory:
    """Return the trajectory of NavSatFix + Imu/Odometry orientation (module docstring)."""
    from scipy.spatial.transform import Rotation, Slerp

    name = bag.select_topic(navsat_topic, (convert.NAVSATFIX,), '--navsat')
    fixes, log, no_fix = [], StampLog(), 0
    for k, message in enumerate(bag.messages([name], f'reading {name}')):
        lat, lon, alt, status = convert.navsat_fix(message.msg)
        if status == convert.NAVSAT_NO_FIX:
            no_fix += 1
            continue
        if not np.all(np.isfinite([lat, lon, alt])):
            raise InputError(f'{name}: message {k} has status {status} (a fix) but its '
                             f'latitude/longitude/altitude is NaN ({lat}, {lon}, {alt}): '
                             'the receiver output is broken')
        fixes.append((lat, lon, alt))
        log.add(message)
    warnings = []
    if no_fix:
        warnings.append(f'{name}: {no_fix} fixes with status NO_FIX dropped')
    if len(fixes) < 2:
        raise InputError(f'{name}: {len(fixes)} usable fix(es) (after {no_fix} NO_FIX); '
                         'need at least 2')
    t = log.times_s(bag.stamp)
    geo = np.array(fixes)
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        k = int(back[0]) + 1
        raise InputError(f'{name}: fix {k} at {t[k]:.6f} s is not after the previous one '
                         f'({t[k - 1]:.6f} s): time goes backwards; use --stamp receive or '
                         'fix the recording')
    o_name, ot, oq = _orientation_stream(bag, imu_topic, odom_topic)
    inside = (t >= ot[0]) & (t <= ot[-1])
    if not inside.all():
        warnings.append(f'{name}: {int((~inside).sum())} fixes outside the orientation '
                        f'stream {o_name} dropped')
    if inside.sum() < 2:
        raise InputError(f'{name} and {o_name} overlap in fewer than 2 fixes: no trajectory')
    rot = Slerp(ot, Rotation.from_quat(oq))(t[inside]).as_matrix()
    traj = GeodeticTrajectory(t[inside], geo[inside, 0], geo[inside, 1], geo[inside, 2], rot)
    traj.warnings = warnings + log.warnings(name, bag.stamp)
    return traj


def stream_scans(bag: BagReader, points_topic: Optional[str], geo: MapGeoreferencer,
                 sink: Callable[[np.ndarray, np.ndarray, np.ndarray], None],
                 time_field: Optional[str] = None, batch_points: int = 1 << 18
                 ) -> Tuple[Dict[str, int], List[str]]:
    """
    Georeference every scan and call ``sink(map_xyz, times, kept_records)`` per batch.

    Scans are gathered into batches of about ``batch_points`` (same fields), so the work
    spreads over the cores; memory stays bounded by a batch. Returns ``(totals,
    warnings)``; ``totals`` sums the counts.
    """
    name = bag.select_topic(points_topic, (convert.POINTCLOUD2,), '--points')
    totals = {'total': 0, 'kept': 0, 'before_span': 0, 'after_span': 0, 'in_gap': 0,
              'non_finite': 0}
    log = StampLog()
    clouds: List[np.ndarray] = []
    stamps: List[np.ndarray] = []

    def flush() -> None:
        cloud = np.concatenate(clouds) if len(clouds) > 1 else clouds[0]
        times = np.concatenate(stamps) if len(stamps) > 1 else stamps[0]
        clouds.clear()
        stamps.clear()
        out, keep, stats = geo.georeference(xyz(cloud), times)
        for key in totals:
            totals[key] += getattr(stats, key)
        if stats.kept:
            sink(out, times[keep], cloud[keep])

    pending = 0
    for message in bag.messages([name], f'georeferencing {name}'):
        log.add(message)
        cloud = convert.cloud_array(message.msg)
        if not len(cloud):
            continue
        try:
            times = point_times(cloud, message_time_s(message, bag.stamp), time_field)
        except InputError as exc:
            raise InputError(f'{name}: {exc}') from None
        if clouds and cloud.dtype != clouds[0].dtype:
            flush()
            pending = 0
        clouds.append(cloud)
        stamps.append(times)
        pending += len(cloud)
        if pending >= batch_points:
            flush()
            pending = 0
    if clouds:
        flush()
    return totals, log.warnings(name, bag.stamp)
