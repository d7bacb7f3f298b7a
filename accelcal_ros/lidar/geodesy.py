r"""
WGS84 geodesy for georeferenced clouds: geodetic <-> ECEF, local ENU frames, map projections.

Frames (REP-103 / REP-105 geographic conventions):

- geodetic: latitude, longitude (deg in files, rad in code), WGS84 ellipsoidal height (m);
- ECEF: WGS84 earth-centred earth-fixed (EPSG:4978), m;
- local ENU at a point: x east, y north, z up along the ellipsoid normal; its rotation
  into ECEF is :func:`ecef_from_enu` (columns east, north, up);
- the map: a projected CRS (UTM by default, the zone of the trajectory's first fix,
  EPSG:326zz north / 327zz south) with the WGS84 ellipsoidal height as the third
  coordinate. No geoid is applied: pyproj's wheels carry no geoid grid and nothing is
  downloaded, so heights stay ellipsoidal (the LAS header and the README say so).

A point is placed exactly: its ECEF position (the body pose at its time, the ENU frame
of that pose) goes through PROJ (:class:`MapProjection`, pipeline ``cart`` inverse then
the projection) -- meridian convergence and the projection's scale factor are applied by
PROJ for every point, never linearised.
"""
from dataclasses import dataclass
from typing import List, Optional, Tuple

from accelcal_ros.errors import InputError
import numpy as np
from numpy.typing import ArrayLike

WGS84_A_M = 6378137.0
"""WGS84 semi-major axis (m)."""
WGS84_F = 1.0 / 298.257223563
"""WGS84 flattening."""
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
"""WGS84 first eccentricity squared."""


def geodetic_to_ecef(lat_rad: ArrayLike, lon_rad: ArrayLike, h_m: ArrayLike) -> np.ndarray:
    """Return ECEF positions ``(N, 3)`` (m) of WGS84 geodetic coordinates (closed form)."""
    lat = np.asarray(lat_rad, dtype=float).reshape(-1)
    lon = np.asarray(lon_rad, dtype=float).reshape(-1)
    h = np.asarray(h_m, dtype=float).reshape(-1)
    sin_lat = np.sin(lat)
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * sin_lat * sin_lat)
    return np.stack([(n + h) * np.cos(lat) * np.cos(lon), (n + h) * np.cos(lat) * np.sin(lon),
                     (n * (1.0 - WGS84_E2) + h) * sin_lat], axis=1)


def ecef_from_enu(lat_rad: ArrayLike, lon_rad: ArrayLike) -> np.ndarray:
    """Return rotations ``(N, 3, 3)`` local ENU -> ECEF (columns: east, north, up)."""
    lat = np.asarray(lat_rad, dtype=float).reshape(-1)
    lon = np.asarray(lon_rad, dtype=float).reshape(-1)
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    zero = np.zeros_like(lat)
    east = np.stack([-so, co, zero], axis=1)
    north = np.stack([-sl * co, -sl * so, cl], axis=1)
    up = np.stack([cl * co, cl * so, sl], axis=1)
    return np.stack([east, north, up], axis=2)


_ENU_FROM_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
_FRD_FROM_FLU = np.diag([1.0, -1.0, -1.0])


def enu_from_body_rpy(roll_rad: ArrayLike, pitch_rad: ArrayLike, yaw_rad: ArrayLike,
                      heading: str = 'enu') -> np.ndarray:
    """
    Return rotations ``(N, 3, 3)`` body (REP-103 x fwd, y left, z up) -> local ENU.

    ``heading='enu'``: REP-103 fixed-axis angles of the body in ENU,
    ``Rz(yaw) Ry(pitch) Rx(roll)``, yaw 0 = east, counter-clockwise positive.
    ``heading='ned'``: the INS form, roll/pitch/heading of the forward-right-down body in
    north-east-down (heading from north, clockwise), converted as
    ``C_enu_flu = T_enu_ned C_ned_frd T_frd_flu``.
    """
    from scipy.spatial.transform import Rotation

    angles = np.stack([np.asarray(yaw_rad, float).reshape(-1),
                       np.asarray(pitch_rad, float).reshape(-1),
                       np.asarray(roll_rad, float).reshape(-1)], axis=1)
    c = Rotation.from_euler('ZYX', angles).as_matrix()
    if heading == 'enu':
        return c
    if heading == 'ned':
        return np.einsum('ij,njk,kl->nil', _ENU_FROM_NED, c, _FRD_FROM_FLU)
    raise InputError(f'unknown heading convention {heading!r} (enu or ned)')


def check_geodetic(lat_deg: np.ndarray, lon_deg: np.ndarray, h_m: np.ndarray
                   ) -> Optional[Tuple[int, str]]:
    """Return ``(index, reason)`` of the first impossible fix, or None."""
    values = np.stack([lat_deg, lon_deg, h_m], axis=1)
    bad = np.flatnonzero(~np.all(np.isfinite(values), axis=1))
    if bad.size:
        return int(bad[0]), 'latitude, longitude or height is NaN or infinite'
    bad = np.flatnonzero(np.abs(lat_deg) > 90.0)
    if bad.size:
        return int(bad[0]), (f'latitude {lat_deg[bad[0]]:g} deg is outside [-90, 90] '
                             '(columns swapped, or radians?)')
    bad = np.flatnonzero(np.abs(lon_deg) > 180.0)
    if bad.size:
        return int(bad[0]), f'longitude {lon_deg[bad[0]]:g} deg is outside [-180, 180]'
    bad = np.flatnonzero(np.abs(h_m) > 1e5)
    if bad.size:
        return int(bad[0]), (f'height {h_m[bad[0]]:g} m is beyond 100 km (millimetres, or '
                             'not an ellipsoidal height in metres?)')
    return None


def utm_zone(lat_deg: float, lon_deg: float) -> int:
    """Return the UTM zone (1..60) of a point, with the Norway and Svalbard exceptions."""
    zone = int(np.floor((lon_deg + 180.0) / 6.0)) % 60 + 1
    if 56.0 <= lat_deg < 64.0 and 3.0 <= lon_deg < 12.0:
        return 32
    if 72.0 <= lat_deg < 84.0 and 0.0 <= lon_deg < 42.0:
        for low, high, z in ((0.0, 9.0, 31), (9.0, 21.0, 33), (21.0, 33.0, 35),
                             (33.0, 42.0, 37)):
            if low <= lon_deg < high:
                return z
    return zone


def utm_epsg(lat_deg: float, lon_deg: float) -> int:
    """Return the EPSG code of WGS 84 / UTM at a point (326zz north, 327zz south)."""
    if not -80.0 <= lat_deg <= 84.0:
        raise InputError(f'latitude {lat_deg:g} deg is outside UTM (80 S .. 84 N): give a '
                         'polar projected CRS with --crs (e.g. EPSG:5041 or EPSG:5042)')
    return (32600 if lat_deg >= 0.0 else 32700) + utm_zone(lat_deg, lon_deg)


def zone_crossing(lat_deg: np.ndarray, lon_deg: np.ndarray, t: np.ndarray) -> Optional[str]:
    """Return a one-line warning when the trajectory leaves its first fix's UTM zone."""
    first = utm_epsg(float(lat_deg[0]), float(lon_deg[0]))
    for k in np.linspace(0, len(lat_deg) - 1, min(len(lat_deg), 2000)).astype(int):
        code = utm_epsg(float(lat_deg[k]), float(lon_deg[k]))
        if code != first:
            return (f'the trajectory crosses from UTM EPSG:{first} into EPSG:{code} at '
                    f't = {t[k]:.3f} s: every point stays in the CRS of the first zone, '
                    f'EPSG:{first} (scale error grows past the zone edge; --crs chooses '
                    'another)')
    return None


def resolve_crs(text: Optional[str], lat_deg: float, lon_deg: float) -> 'MapProjection':
    """Return the map projection: ``text`` (``EPSG:NNNN``, any pyproj CRS) or UTM here."""
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    if text is None:
        return MapProjection(CRS.from_epsg(utm_epsg(lat_deg, lon_deg)))
    try:
        crs = CRS.from_user_input(text)
    except CRSError:
        raise InputError(f'unknown CRS {text!r}: give a projected CRS PROJ knows, e.g. '
                         'EPSG:32637 (WGS 84 / UTM 37N)') from None
    if crs.is_compound:
        horizontal = next((sub for sub in crs.sub_crs_list if sub.is_projected), None)
        hint = (f'EPSG:{horizontal.to_epsg()}' if horizontal is not None
                and horizontal.to_epsg() else 'its horizontal CRS alone')
        raise InputError(f'CRS {text!r} ({crs.name}) has a vertical part: the heights written '
                         'are WGS84 ellipsoidal (no geoid grid is applied), which a file '
                         f'labelled with it would misstate; give {hint}')
    if not crs.is_projected:
        raise InputError(f'CRS {text!r} ({crs.name}) is not a projected CRS: a cloud needs '
                         'metric map coordinates (e.g. EPSG:32637)')
    return MapProjection(crs)


@dataclass
class ProjectionFactors:
    """Meridian convergence (deg, grid north from true north) and point scale factor."""

    convergence_deg: float
    scale: float


class MapProjection:
    """A projected CRS (plus ellipsoidal height) fed with ECEF points, through PROJ."""

    def __init__(self, crs: 'object') -> None:
        from pyproj import CRS, Transformer

        self.crs = crs if isinstance(crs, CRS) else CRS.from_user_input(crs)
        self.crs_3d = self.crs.to_3d()
        self._from_ecef = Transformer.from_crs(CRS.from_epsg(4978), self.crs_3d,
                                               always_xy=True)
        self._from_geodetic = Transformer.from_crs(CRS.from_epsg(4979), self.crs_3d,
                                                   always_xy=True)

    @property
    def name(self) -> str:
        """Return ``EPSG:NNNN (name)`` or the CRS name."""
        code = self.crs.to_epsg()
        return f'EPSG:{code} ({self.crs.name})' if code else self.crs.name

    def wkt(self) -> str:
        """Return the horizontal CRS as OGC WKT 1 (what LAS 1.4 readers parse)."""
        return str(self.crs.to_wkt('WKT1_GDAL'))

    def from_ecef(self, xyz: ArrayLike, threads: Optional[int] = None) -> np.ndarray:
        """
        Return map coordinates ``(N, 3)`` (easting, northing, ellipsoidal height, m).

        Large arrays are split over ``threads`` (default: the CPU count, at most 4): PROJ
        runs without the GIL and pyproj's transformers are thread-safe.
        """
        import os
        from concurrent.futures import ThreadPoolExecutor

        pts = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
        out = np.empty_like(pts)
        threads = threads or min(4, os.cpu_count() or 1)
        parts = threads if len(pts) >= 65536 * threads else 1
        bounds = np.linspace(0, len(pts), parts + 1).astype(int)

        def work(k: int) -> None:
            a, b = int(bounds[k]), int(bounds[k + 1])
            part = pts[a:b] if b - a > 1 else np.repeat(pts[a:b], 2, axis=0)
            x, y, z = self._from_ecef.transform(part[:, 0], part[:, 1], part[:, 2])
            out[a:b, 0], out[a:b, 1], out[a:b, 2] = x[:b - a], y[:b - a], z[:b - a]

        if parts == 1:
            work(0)
        else:
            with ThreadPoolExecutor(max_workers=parts) as pool:
                list(pool.map(work, range(parts)))
        if not np.all(np.isfinite(out)):
            raise InputError(f'some points lie outside the domain of {self.name}: give a '
                             'CRS that covers the survey (--crs)')
        return out

    def from_geodetic(self, lat_deg: ArrayLike, lon_deg: ArrayLike, h_m: ArrayLike
                      ) -> np.ndarray:
        """Return map coordinates ``(N, 3)`` of geodetic points (deg, deg, m)."""
        lon = np.asarray(lon_deg, float).reshape(-1)
        lat = np.asarray(lat_deg, float).reshape(-1)
        h = np.asarray(h_m, float).reshape(-1)
        n = len(lon)
        if n == 1:  # pyproj takes a 1-element array for a scalar point (numpy warns)
            lon, lat, h = np.repeat(lon, 2), np.repeat(lat, 2), np.repeat(h, 2)
        x, y, z = self._from_geodetic.transform(lon, lat, h)
        return np.stack([x, y, z], axis=1)[:n]

    def factors(self, lat_deg: float, lon_deg: float) -> ProjectionFactors:
        """Return the projection's convergence and scale factor at a point (PROJ)."""
        from pyproj import Proj

        f = Proj(self.crs).get_factors(lon_deg, lat_deg)
        return ProjectionFactors(float(f.meridian_convergence), float(f.meridional_scale))

    def outside_area_of_use(self, lat_deg: ArrayLike, lon_deg: ArrayLike) -> Optional[str]:
        """
        Return a warning when a fix (deg) lies outside the CRS's area of use, else None.

        The area of use is PROJ's (west, south, east, north bounds, deg); a CRS without one
        (a custom PROJ string) gives None.
        """
        area = self.crs.area_of_use
        if area is None:
            return None
        lat = np.asarray(lat_deg, float).reshape(-1)
        lon = np.asarray(lon_deg, float).reshape(-1)
        west, south, east, north = area.bounds
        inside_lon = ((lon >= west) & (lon <= east) if west <= east
                      else (lon >= west) | (lon <= east))   # an area across the antimeridian
        outside = np.flatnonzero(~(inside_lon & (lat >= south) & (lat <= north)))
        if not outside.size:
            return None
        k = int(outside[0])   # PROJ's scale factor there can be meaningless: not quoted
        return (f'{outside.size} of {lat.size} fixes (the first at {lat[k]:.6f}, {lon[k]:.6f}) '
                f'lie outside the area of use of {self.name} (lon {west:g}..{east:g}, lat '
                f'{south:g}..{north:g}), where its coordinates are distorted or invalid: is '
                'this the CRS of the survey?')

    def describe(self, lat_deg: float, lon_deg: float) -> List[str]:
        """Return report lines: the CRS, and the convergence and scale at a point."""
        f = self.factors(lat_deg, lon_deg)
        return [f'map CRS {self.name}, heights WGS84 ellipsoidal (no geoid)',
                f'at {lat_deg:.6f}, {lon_deg:.6f}: meridian convergence '
                f'{f.convergence_deg:.4f} deg, scale factor {f.scale:.6f} (applied per point)']
