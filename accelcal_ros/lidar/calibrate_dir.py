"""
Boresight calibration of a directory of static positions (core of ``accelcal boresight``).

``DIR`` holds, per static position ``NN``, one cloud ``posNN.pcd`` (or ``.ply``; LiDAR
frame, m) and one IMU log ``posNN_imu.csv`` (``t,ax,ay,az[,gx,gy,gz]``, s, m/s^2, rad/s)
covering that position's still period. The longest static segment of each log gives the
gravity; the cloud gives the floor; :func:`accelcal_ros.lidar.boresight.calibrate_boresight`
does the rest. Also writes the result (YAML, atomic) and draws Fig. 10 (per-position
errors).
"""
import os
import re
from typing import Any, Dict, List, Optional, Tuple

from accelcal_ros.errors import AccelcalError, InputError
from accelcal_ros.fileio import write_text_atomic
from accelcal_ros.lidar.boresight import (BoresightResult, calibrate_boresight, PathLike,
                                          StaticPosition)
from accelcal_ros.lidar.cloud import read_cloud, xyz
from accelcal_ros.lidar.imu_log import read_imu_csv
from accelcal_ros.lidar.plane_fit import FloorSearch
from accelcal_ros.lidar.static_segments import longest_static_segment
from accelcal_ros.recording.progress import track
from accelcal_ros.sensor.model import SensorModel
from accelcal_ros.textformats import dump_yaml
import numpy as np

_CLOUD = re.compile(r'^(pos\d+)\.(pcd|ply)$', re.IGNORECASE)


def list_positions(directory: PathLike) -> List[Tuple[str, str, str]]:
    """Return ``[(name, cloud_path, imu_path)]`` sorted by name; InputError if none."""
    directory = os.fspath(directory)
    if not os.path.isdir(directory):
        raise InputError(f'{directory}: not a directory')
    found = []
    for entry in sorted(os.listdir(directory)):
        match = _CLOUD.match(entry)
        if not match:
            continue
        name = match.group(1)
        found.append((name, os.path.join(directory, entry),
                      os.path.join(directory, f'{name}_imu.csv')))
    if not found:
        raise InputError(f'{directory}: no posNN.pcd or posNN.ply files (one cloud and one '
                         'posNN_imu.csv per static position)')
    names = [f[0] for f in found]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise InputError(f'{directory}: both .pcd and .ply for {dupes}; keep one')
    return found


def load_positions(directory: PathLike, model: Optional[SensorModel] = None,
                   skip_bad_files: bool = False, static_options: Optional[Dict[str, Any]] = None
                   ) -> Tuple[List[StaticPosition], Dict[str, str]]:
    """
    Read every position; returns ``(positions, dropped)``.

    A position whose IMU log has no still period is dropped with the reason; an unreadable
    file is an error naming file and line (or, with ``skip_bad_files``, dropped with it).
    """
    positions, dropped = [], {}
    for name, cloud_path, imu_path in track(list_positions(directory),
                                            'boresight: reading positions'):
        try:
            if not os.path.exists(imu_path):
                raise InputError(f'{imu_path}: IMU log missing for {name}')
            cloud = read_cloud(cloud_path)
            log = read_imu_csv(imu_path)
        except AccelcalError as exc:
            if not skip_bad_files:
                raise
            dropped[name] = str(exc)
            continue
        seg = longest_static_segment(log.t, log.accel, log.gyro, model,
                                     **(static_options or {}))
        if seg is None:
            dropped[name] = (f'{imu_path}: no static segment (the IMU never holds still for '
                             'the minimum duration)')
            continue
        pts = xyz(cloud) if len(cloud) else np.zeros((0, 3))
        positions.append(StaticPosition(name, pts, seg.gravity_m_s2, seg.direction_std_rad(),
                                        calibrated=model is not None))
    return positions, dropped


def calibrate_directory(directory: PathLike, prior: Optional[np.ndarray] = None,
                        model: Optional[SensorModel] = None,
                        search: Optional[FloorSearch] = None, weighting: str = 'equal',
                        skip_bad_files: bool = False) -> BoresightResult:
    """Return the :class:`BoresightResult` of a directory (drops merged in)."""
    positions, dropped = load_positions(directory, model, skip_bad_files)
    if not positions:
        from accelcal_ros.errors import CalibrationError

        reasons = '; '.join(f'{k}: {v}' for k, v in dropped.items())
        raise CalibrationError(f'no usable position in {directory}: {reasons}')
    result = calibrate_boresight(positions, prior=prior, search=search, weighting=weighting)
    merged = dict(dropped)
    merged.update(result.dropped)
    result.dropped = merged
    return result


def write_result(path: PathLike, result: BoresightResult,
                 extra: Optional[Dict[str, Any]] = None) -> None:
    """Write the boresight YAML atomically."""
    data = result.to_dict()
    if extra:
        data.update(extra)
    write_text_atomic(path, dump_yaml(data))


def report_lines(result: BoresightResult) -> List[str]:
    """Return the human-readable report of a result (what the CLI prints)."""
    r, p, y = result.rpy_deg
    sr, sp, sy = result.rpy_std_deg
    lines = [f'boresight (LiDAR -> IMU): roll {r:+.4f} deg, pitch {p:+.4f} deg, '
             f'yaw {y:+.4f} deg  (1-sigma {sr:.4f}, {sp:.4f}, {sy:.4f} deg)',
             f'positions used: {len(result.positions)}; per-position error |R n - g| (deg), '
             f'mean {result.mean_error_deg:.4f}, max '
             f'{np.max(result.per_position_error_deg):.4f}:']
    held = result.holdout['per_position']
    for name, err, h, inl in zip(result.positions, result.per_position_error_deg, held,
                                 result.inliers):
        ho = '   n/a' if h is None else f'{h:.4f}'
        lines.append(f'  {name}: {err:.4f}  (hold-out {ho}, floor inliers {inl})')
    summary = result.holdout
    if summary['mean'] is not None:
        lines.append(f'hold-out (fit even, test odd and vice versa): mean '
                     f'{summary["mean"]:.4f} deg, max {summary["max"]:.4f} deg' + (
                         '' if summary['even_vs_odd_rotation'] is None else
                         f'; even vs odd fit differ by {summary["even_vs_odd_rotation"]:.4f} deg'))
    for name, reason in result.dropped.items():
        lines.append(f'dropped {name}: {reason}')
    for text in result.warnings:
        lines.append(f'warning: {text}')
    return lines


def plot_errors(path: PathLike, result: BoresightResult, paper_mean_deg: float = 0.3) -> None:
    """Draw paper B Fig. 10 (per-position angle between R n and g) as a PNG, atomically."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from accelcal_ros.fileio import write_with_atomic

    fig, ax = plt.subplots(figsize=(8, 3.6), dpi=110)
    x = np.arange(len(result.positions))
    ax.bar(x - 0.2, result.per_position_error_deg, 0.4, label='fit on all positions')
    held = np.array([np.nan if v is None else v for v in result.holdout['per_position']])
    ax.bar(x + 0.2, held, 0.4, label='hold-out (fit on the other parity)')
    ax.axhline(paper_mean_deg, color='k', ls='--', lw=1, label=f'paper B mean '
               f'{paper_mean_deg:g} deg')
    ax.set_xticks(x)
    ax.set_xticklabels([n.replace('pos', '') for n in result.positions])
    ax.set_xlabel('position')
    ax.set_ylabel('angle(R n, g) [deg]')
    ax.set_title(f'LiDAR-IMU boresight: mean {result.mean_error_deg:.3f} deg over '
                 f'{len(x)} positions')
    ax.legend(fontsize=8)
    fig.tight_layout()
    write_with_atomic(path, lambda h: fig.savefig(h, format='png'), binary=True)
    plt.close(fig)
