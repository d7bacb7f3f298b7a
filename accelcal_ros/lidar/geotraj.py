r"""
Geodetic (GNSS/INS) trajectories and georeferencing straight into a map projection.

Trajectory CSV ``t,lat,lon,h,roll,pitch,yaw``: time (s, the clock of the points' times),
WGS84 latitude and longitude (deg), ellipsoidal height (m), and the body's attitude
(deg). ``heading='enu'`` (default): the REP-103 body (x forward, y left, z up) in the local
east-north-up frame, ``Rz(yaw) Ry(pitch) Rx(roll)``, yaw 0 = east, counter-clockwise;
``heading='ned'``: the INS form, roll/pitch/heading of the forward-right-down body in
north-east-down, heading from north, clockwise
(:func:`accelcal_ros.lidar.geodesy.enu_from_body_rpy`).

Each point (LiDAR frame, its own time ``t``) is placed as

.. math::  X = r(t) + C_{E}(t) (R\, p_L + l), \qquad (E, N, h) = \mathrm{proj}(X)

with ``r`` the body position in ECEF and ``C_E = C_{ecef \leftarrow enu}(\varphi,
\lambda) C_{enu \leftarrow body}`` the body attitude in ECEF, both interpolated to ``t``
(position linearly in ECEF, attitude by slerp; :mod:`accelcal_ros.lidar.georef`), and
``proj`` the map projection applied by PROJ to every point
(:class:`accelcal_ros.lidar.geodesy.MapProjection`): the offset ``R p + l`` lives in the
ENU frame of the pose, and the meridian convergence and scale factor at the point are
PROJ's, not a linearisation. Points outside the trajectory, or between two poses more
than ``max_gap_s`` apart, are dropped and counted (never extrapolated).
"""
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

from accelcal_ros.errors import FileFormatError, InputError
from accelcal_ros.lidar.geodesy import (check_geodetic, ecef_from_enu, enu_from_body_rpy,
                                        geodetic_to_ecef, MapProjection, resolve_crs,
                                        zone_crossing)
from accelcal_ros.lidar.georef import georeference, GeorefStats, PoseInterpolator
from accelcal_ros.lidar.poses import PoseStream
from accelcal_ros.schema import TRAJECTORY_CSV
import numpy as np
from numpy.typing import ArrayLike

TRAJECTORY_COLUMNS = TRAJECTORY_CSV.required


@dataclass
class GeodeticTrajectory:
    """Body poses: ``t`` (s), WGS84 lat/lon (deg), h (m), rotations body -> ENU (N, 3, 3)."""

    t: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray
    enu_from_body: np.ndarray
    warnings: List[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        """Check sizes, fixes and strictly increasing time (one-line InputErrors)."""
        self.t = np.asarray(self.t, dtype=float).reshape(-1)
        self.lat_deg = np.asarray(self.lat_deg, dtype=float).reshape(-1)
        self.lon_deg = np.asarray(self.lon_deg, dtype=float).reshape(-1)
        self.h_m = np.asarray(self.h_m, dtype=float).reshape(-1)
        self.enu_from_body = np.asarray(self.enu_from_body, dtype=float).reshape(-1, 3, 3)
        n = self.t.size
        if not (self.lat_deg.size == self.lon_deg.size == self.h_m.size
                == len(self.enu_from_body) == n):
            raise InputError('trajectory: times, fixes and attitudes differ in number')
        if n < 2:
            raise InputError(f'trajectory needs at least 2 poses to interpolate, got {n}')
        problem = trajectory_problem(self.t, self.lat_deg, self.lon_deg, self.h_m)
        if problem is not None:
            raise InputError(f'trajectory pose {problem[0]}: {problem[1]}')

    @property
    def span(self) -> Tuple[float, float]:
        """Return ``(t_first, t_last)`` (s)."""
        return float(self.t[0]), float(self.t[-1])

    def ecef_poses(self) -> PoseStream:
        """Return the poses in ECEF: positions (m) and quaternions body -> ECEF (xyzw)."""
        from scipy.spatial.transform import Rotation

        lat, lon = np.radians(self.lat_deg), np.radians(self.lon_deg)
        position = geodetic_to_ecef(lat, lon, self.h_m)
        c = np.einsum('nij,njk->nik', ecef_from_enu(lat, lon), self.enu_from_body)
        return PoseStream(self.t, position, Rotation.from_matrix(c).as_quat())

    def projection(self, crs: Optional[str] = None) -> MapProjection:
        """Return the map CRS: ``crs``, else the UTM zone of the first fix."""
        return resolve_crs(crs, float(self.lat_deg[0]), float(self.lon_deg[0]))

    def zone_warning(self) -> Optional[str]:
        """Return the zone-crossing warning line (None inside one UTM zone)."""
        return zone_crossing(self.lat_deg, self.lon_deg, self.t)


def trajectory_problem(t: np.ndarray, lat_deg: np.ndarray, lon_deg: np.ndarray,
                       h_m: np.ndarray) -> Optional[Tuple[int, str]]:
    """Return ``(index, reason)`` of the first bad pose (fix or time), or None."""
    if not np.all(np.isfinite(t)):
        return int(np.flatnonzero(~np.isfinite(t))[0]), 'time is NaN or infinite'
    problem = check_geodetic(lat_deg, lon_deg, h_m)
    if problem is not None:
        return problem
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        k = int(back[0]) + 1
        return k, (f'time {t[k]:.6f} s is not after the previous pose ({t[k - 1]:.6f} s): '
                   'time goes backwards or repeats; sort the trajectory by time')
    return None


MAX_ATTITUDE_DEG = 1e5
"""Largest |roll|, |pitch|, |yaw| read (deg; an unwrapped heading of 277 turns): beyond it a
value is corrupt (1e308 deg was read and gave an arbitrary orientation)."""


def read_trajectory_csv(path: str, heading: str = 'enu') -> GeodeticTrajectory:
    """
    Read ``t,lat,lon,h,roll,pitch,yaw`` (deg); errors name the file and line.

    Angles are finite and within +-:data:`MAX_ATTITUDE_DEG`.
    """
    from accelcal_ros.textformats import read_numeric_csv

    cols = read_numeric_csv(path, TRAJECTORY_COLUMNS)
    t = cols['t']
    if t.size < 2:
        raise FileFormatError(path, f'needs at least 2 poses, found {t.size}')
    problem = trajectory_problem(t, cols['lat'], cols['lon'], cols['h'])
    if problem is None:
        att = np.stack([cols['roll'], cols['pitch'], cols['yaw']], axis=1)
        bad = np.flatnonzero(~np.all(np.isfinite(att), axis=1))
        problem = (int(bad[0]), 'roll, pitch or yaw is NaN or infinite') if bad.size else None
        far = np.flatnonzero(np.any(np.abs(att) > MAX_ATTITUDE_DEG, axis=1))
        if problem is None and far.size:
            problem = (int(far[0]), f'roll, pitch or yaw beyond +-{MAX_ATTITUDE_DEG:g} deg '
                                    f'({", ".join(f"{v:g}" for v in att[far[0]])}): a corrupt '
                                    'value (its sine and cosine would be noise)')
    if problem is not None:
        raise FileFormatError(path, problem[1], problem[0] + 2)
    rot = enu_from_body_rpy(np.radians(cols['roll']), np.radians(cols['pitch']),
                            np.radians(cols['yaw']), heading)
    return GeodeticTrajectory(t, cols['lat'], cols['lon'], cols['h'], rot)


def write_trajectory_csv(path: str, traj: GeodeticTrajectory) -> None:
    """Write a trajectory as ``t,lat,lon,h,roll,pitch,yaw`` (ENU form, deg) atomically."""
    from scipy.spatial.transform import Rotation

    from accelcal_ros.fileio import write_text_atomic

    ypr = np.degrees(Rotation.from_matrix(traj.enu_from_body).as_euler('ZYX'))
    table = np.column_stack([traj.t, traj.lat_deg, traj.lon_deg, traj.h_m, ypr[:, 2],
                             ypr[:, 1], ypr[:, 0]])
    lines = [','.join(TRAJECTORY_COLUMNS)]
    lines += [','.join(f'{v:.12f}' if k in (1, 2) else f'{v:.9g}' if k else f'{v:.9f}'
                       for k, v in enumerate(row)) for row in table.tolist()]
    write_text_atomic(path, '\n'.join(lines) + '\n')


class MapGeoreferencer:
    """Georeference LiDAR points straight into a map CRS along a geodetic trajectory."""

    def __init__(self, trajectory: GeodeticTrajectory, boresight: ArrayLike,
                 lever_arm_m: ArrayLike = (0.0, 0.0, 0.0), crs: Optional[str] = None,
                 max_gap_s: Optional[float] = None) -> None:
        self.trajectory = trajectory
        self.projection = trajectory.projection(crs)
        self.interp = PoseInterpolator(trajectory.ecef_poses())
        self.boresight = boresight
        self.lever_arm_m = lever_arm_m
        self.max_gap_s = max_gap_s
        self.crs_given = crs is not None
        lat0, lon0 = float(trajectory.lat_deg[0]), float(trajectory.lon_deg[0])
        self.origin_m = self.projection.from_geodetic(lat0, lon0, trajectory.h_m[0])[0]

    def report_lines(self) -> List[str]:
        """Return the CRS, convergence and scale at the first fix, and zone warnings."""
        lines = self.projection.describe(float(self.trajectory.lat_deg[0]),
                                         float(self.trajectory.lon_deg[0]))
        return lines

    def warnings(self) -> List[str]:
        """
        Return warnings about the trajectory.

        A zone crossing when the zone was chosen here; fixes outside the area of use of a
        CRS given with ``--crs`` (e.g. UTM zone 1N for Moscow: scale factor 1.055).
        """
        if self.crs_given:
            warning = self.projection.outside_area_of_use(self.trajectory.lat_deg,
                                                          self.trajectory.lon_deg)
        else:
            warning = self.trajectory.zone_warning()
        return list(self.trajectory.warnings) + ([warning] if warning else [])

    def georeference(self, points: ArrayLike, times: ArrayLike
                     ) -> Tuple[np.ndarray, np.ndarray, GeorefStats]:
        """Return ``(map points (M, 3) E N h, kept mask (N,), stats)``."""
        import os

        threads = min(4, os.cpu_count() or 1)
        chunk = max(65536, len(np.asarray(times).reshape(-1)) // threads + 1)
        ecef, keep, stats = georeference(points, times, self.interp, self.boresight,
                                         self.lever_arm_m, threads=threads, chunk=chunk,
                                         max_gap_s=self.max_gap_s)
        return self.projection.from_ecef(ecef, threads), keep, stats
