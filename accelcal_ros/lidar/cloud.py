"""
Point clouds as numpy structured arrays: building, field access, per-point time, files.

Fields: ``x y z`` (m, float32 or float64, in the frame of the file: the LiDAR frame for
raw scans, the navigation frame for georeferenced clouds), optional ``intensity``,
``ring`` (laser index, 0 = lowest beam) and a per-point time. Per-point time fields as
drivers write them:

- ``time`` (float32 s, relative to the scan's stamp; velodyne_pointcloud),
- ``t`` (uint32 ns, relative; ouster-ros),
- ``timestamp`` (float64 s, absolute; Hesai, Livox, many PCD exports).

:func:`point_times` turns any of them into absolute seconds given the scan's base time.
"""
import os
from typing import Optional, Union

from accelcal_ros.errors import FileFormatError, InputError
import numpy as np
from numpy.typing import ArrayLike

PathLike = Union[str, 'os.PathLike[str]']

TIME_FIELDS = ('time', 't', 'timestamp')
"""Recognised per-point time fields, in order of preference."""


def make_cloud(xyz: ArrayLike, intensity: Optional[ArrayLike] = None,
               ring: Optional[ArrayLike] = None, time: Optional[ArrayLike] = None,
               time_field: str = 'time', double: bool = False) -> np.ndarray:
    """Build a structured cloud from ``(N, 3)`` points and optional per-point fields."""
    xyz = np.asarray(xyz, dtype=float).reshape(-1, 3)
    ftype = 'f8' if double else 'f4'
    descr = [('x', ftype), ('y', ftype), ('z', ftype)]
    if intensity is not None:
        descr.append(('intensity', 'f4'))
    if ring is not None:
        descr.append(('ring', 'u2'))
    if time is not None:
        descr.append((time_field, {'time': 'f4', 't': 'u4', 'timestamp': 'f8'}.get(
            time_field, 'f8')))
    cloud = np.zeros(len(xyz), dtype=descr)
    cloud['x'], cloud['y'], cloud['z'] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    if intensity is not None:
        cloud['intensity'] = intensity
    if ring is not None:
        cloud['ring'] = ring
    if time is not None:
        cloud[time_field] = time
    return cloud


def xyz(cloud: np.ndarray) -> np.ndarray:
    """Return the ``(N, 3)`` float64 points of a structured cloud (InputError without x y z)."""
    names = cloud.dtype.names or ()
    missing = [n for n in ('x', 'y', 'z') if n not in names]
    if missing:
        raise InputError(f'cloud has no field(s) {missing}; fields: {list(names)}')
    out = np.empty((len(cloud), 3))
    out[:, 0], out[:, 1], out[:, 2] = cloud['x'], cloud['y'], cloud['z']
    return out


def finite_mask(points: ArrayLike) -> np.ndarray:
    """Return a boolean mask of the rows of ``(N, 3)`` points that are all finite."""
    return np.all(np.isfinite(points), axis=1)


def time_field_of(cloud: np.ndarray, field: Optional[str] = None) -> str:
    """Return the name of the per-point time field, or raise InputError naming the fields."""
    names = cloud.dtype.names or ()
    if field:
        if field not in names:
            raise InputError(f'cloud has no per-point time field {field!r}; fields: '
                             f'{list(names)}')
        return field
    for name in TIME_FIELDS:
        if name in names:
            return name
    raise InputError('cloud has no per-point time field (one of time, t, timestamp); '
                     f'fields: {list(names)}. Georeferencing needs the time of every point: '
                     'record with the driver option that keeps it (e.g. velodyne '
                     '"organize_cloud: false" keeps "time")')


def point_times(cloud: np.ndarray, base_time_s: float = 0.0,
                field: Optional[str] = None) -> np.ndarray:
    """
    Return absolute per-point times (s, float64).

    ``time`` (s) and ``t`` (ns) are relative to ``base_time_s`` (the scan's header stamp);
    ``timestamp`` is absolute already unless it is small (< 1e6 s), in which case it is
    taken as relative too.
    """
    name = time_field_of(cloud, field)
    values = np.asarray(cloud[name], dtype=np.float64)
    if name == 't':
        return base_time_s + values * 1e-9
    if name == 'timestamp' and values.size and np.nanmax(np.abs(values)) >= 1e6:
        return values
    return base_time_s + values


def read_cloud(path: PathLike) -> np.ndarray:
    """Read a ``.pcd`` or ``.ply`` file into a structured array."""
    from accelcal_ros.lidar.pcd import read_pcd
    from accelcal_ros.lidar.ply import read_ply

    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext == '.pcd':
        return read_pcd(path)[0]
    if ext == '.ply':
        return read_ply(path)
    raise FileFormatError(path, f'unknown point cloud extension {ext!r} (.pcd or .ply)')


def write_cloud(path: PathLike, cloud: np.ndarray, data: str = 'binary') -> None:
    """Write a ``.pcd`` (``data``: ascii, binary, binary_compressed) or ``.ply`` atomically."""
    from accelcal_ros.lidar.pcd import write_pcd
    from accelcal_ros.lidar.ply import write_ply

    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext == '.pcd':
        write_pcd(path, cloud, data)
    elif ext == '.ply':
        write_ply(path, cloud, binary=data != 'ascii')
    else:
        raise InputError(f'{path}: unknown point cloud extension {ext!r} (.pcd or .ply)')
