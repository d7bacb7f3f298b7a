"""
The live map of ``cloud_assembler`` in a projected CRS: a ``map`` frame anchored at a UTM origin.

When the odometry is in a projected CRS (``map_crs``, e.g. an INS or robot_localization
publishing UTM easting/northing/ellipsoidal height), coordinates are millions of metres:
a float32 PointCloud2 field steps 0.5 m at 6e6 m. The node therefore publishes in a
``map`` frame whose origin is the UTM point ``map_origin`` (``map = utm - origin``, axes
parallel: x east along grid, y north along grid, z up), which it logs; the accumulated
cloud keeps float64 CRS coordinates, and ``save`` writes them to LAS/LAZ with the CRS
(:mod:`accelcal_ros.lidar.las`), optionally thinned to one point per voxel.
"""
import os
from typing import Optional, Sequence

from accelcal_ros.errors import InputError
import numpy as np
from numpy.typing import ArrayLike


def choose_origin(given: Sequence[float], first_position: ArrayLike) -> np.ndarray:
    """Return ``given`` (E, N, h) or the first pose rounded to 1 km (h to 100 m)."""
    if len(given) == 3:
        return np.asarray(given, dtype=float)
    if len(given):
        raise InputError(f'map_origin needs 3 values (easting northing height), got {given}')
    p = np.asarray(first_position, dtype=float).reshape(3)
    return np.array([np.round(p[0], -3), np.round(p[1], -3), np.round(p[2], -2)])


def shift_to_map(cloud: np.ndarray, origin: ArrayLike) -> np.ndarray:
    """Return a copy of a structured cloud with ``x y z`` minus ``origin`` (map frame)."""
    o = np.asarray(origin, dtype=float).reshape(3)
    out = cloud.copy()
    out['x'] = cloud['x'] - o[0]
    out['y'] = cloud['y'] - o[1]
    out['z'] = cloud['z'] - o[2]
    return out


def voxel_thin(cloud: np.ndarray, voxel_m: float) -> np.ndarray:
    """Keep the first point (in time order) of every ``voxel_m`` cube (0: all points)."""
    if voxel_m <= 0.0 or len(cloud) == 0:
        return cloud
    keys = np.floor(np.stack([cloud['x'], cloud['y'], cloud['z']], axis=1) / voxel_m)
    keys -= keys.min(axis=0)
    _, first = np.unique(keys.astype(np.int64), axis=0, return_index=True)
    return cloud[np.sort(first)]


def map_output_problem(path: str, crs: str) -> Optional[str]:
    """Return why ``path`` cannot hold the map of a ``crs`` (empty: none) cloud, or None."""
    from accelcal_ros.lidar.las import is_las_path

    if path and is_las_path(path) and not crs:
        return (f'{os.path.basename(path)}: LAS/LAZ needs map_crs (e.g. EPSG:32637), which is '
                'read-only: set it at start, or write .ply or .pcd')
    return None


def write_map_cloud(path: str, cloud: np.ndarray, crs: str, voxel_m: float = 0.0,
                    chunk: int = 1 << 20) -> int:
    """
    Write an accumulated CRS cloud (x y z float64, [intensity ring] timestamp) to ``path``.

    ``.laz``/``.las``: LAS 1.4 with the CRS (atomic, streamed by ``chunk``); ``.ply``/
    ``.pcd``: float64 as they are. Returns the number of points written.
    """
    from accelcal_ros.lidar.cloud import write_cloud, xyz
    from accelcal_ros.lidar.geodesy import resolve_crs
    from accelcal_ros.lidar.las import is_las_path, is_unix_clock, LasCloudWriter

    cloud = voxel_thin(cloud, voxel_m)
    if not is_las_path(path):
        write_cloud(path, cloud)
        return len(cloud)
    problem = map_output_problem(path, crs)
    if problem:
        raise InputError(problem)
    if not len(cloud):
        raise InputError('no georeferenced point yet: nothing to save')
    projection = resolve_crs(crs, 0.0, 0.0)
    names = cloud.dtype.names or ()
    pts = xyz(cloud)
    times = cloud['timestamp']
    ring = 'ring' in names
    with LasCloudWriter(path, projection.wkt(), pts[0], is_unix_clock(times), ring,
                        projection.name) as writer:
        for a in range(0, len(cloud), chunk):
            part = cloud[a:a + chunk]
            writer.write(pts[a:a + chunk], times[a:a + chunk],
                         part['intensity'] if 'intensity' in names else None,
                         part['ring'] if ring else None)
    return len(cloud)


def origin_line(origin: Optional[ArrayLike], crs: str) -> str:
    """Return the log line that states the map frame's origin."""
    if origin is None:
        return f'map frame: origin not set yet (the first pose in {crs}, rounded, is used)'
    e, n, h = np.asarray(origin, dtype=float).reshape(3)
    return (f'map frame anchored at {crs} E {e:.3f} N {n:.3f} h {h:.3f} m (map = '
            f'{crs} - origin; the utm -> map transform is this translation)')
