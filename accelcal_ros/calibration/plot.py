"""
Plot of a calibration (as paper A's Fig. 1): captured points against the unit sphere.

Left: the raw mean reading of every position (the sensitivity ellipsoid's points) and the
same readings corrected by the calibration, against the unit sphere. Right: the eq. (5)
residual of every position in mg (dropped positions in red). Needs matplotlib.
"""
import io
from typing import Sequence

from accelcal_ros.errors import InputError
from accelcal_ros.fileio import write_bytes_atomic
from accelcal_ros.sensor.model import SensorModel
import numpy as np
from numpy.typing import ArrayLike


def plot_calibration(path: str, captures_g: ArrayLike, residuals_g: ArrayLike,
                     sensor_model: SensorModel, dropped: Sequence[int] = (),
                     title: str = '') -> None:
    """Write a PNG of the calibration to ``path`` (atomically)."""
    try:
        import matplotlib
        matplotlib.use('Agg')
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - optional extra
        raise InputError('plot-calibration needs matplotlib (pip install matplotlib)') from exc
    captures = np.asarray(captures_g, dtype=float).reshape(-1, 3)
    residuals = np.asarray(residuals_g, dtype=float).reshape(-1)
    corrected = sensor_model.correct(captures)
    fig = plt.figure(figsize=(11, 5))
    ax = fig.add_subplot(1, 2, 1, projection='3d')
    u, v = np.mgrid[0:2 * np.pi:36j, 0:np.pi:18j]
    ax.plot_wireframe(np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v),
                      color='0.8', linewidth=0.5)
    ax.scatter(*captures.T, color='tab:orange', s=25, label='raw mean readings (g)')
    ax.scatter(*corrected.T, color='tab:blue', s=25, label='calibrated')
    ax.set_xlabel('x (g)')
    ax.set_ylabel('y (g)')
    ax.set_zlabel('z (g)')
    ax.legend(loc='upper left', fontsize=8)
    ax.set_title('positions against the unit sphere')
    bx = fig.add_subplot(1, 2, 2)
    colors = ['tab:red' if k in set(dropped) else 'tab:blue' for k in range(len(residuals))]
    bx.bar(np.arange(len(residuals)), residuals * 1e3, color=colors)
    bx.axhline(0.0, color='k', linewidth=0.5)
    bx.set_xlabel('position')
    bx.set_ylabel('residual |f| - 1 (mg)')
    bx.set_title('per-position residual (red: dropped)')
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format='png', dpi=100)
    plt.close(fig)
    write_bytes_atomic(path, buffer.getvalue())


def plot_calibration_file(path: str, calibration_path: str) -> None:
    """Write the plot of a calibration file (which stores its captures) to ``path``."""
    from accelcal_ros.sensor.calibration_file import load_calibration
    from accelcal_ros.errors import FileFormatError

    record = load_calibration(calibration_path)
    data = record.data
    try:
        captures = np.asarray(data.get('captures_g') or [], dtype=float).reshape(-1, 3)
        residuals = np.asarray(data.get('residuals_g') or [], dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise FileFormatError(calibration_path, 'captures_g must be a list of [x, y, z] and '
                              'residuals_g a list of numbers') from None
    if len(captures) == 0 or len(residuals) != len(captures):
        raise FileFormatError(calibration_path, 'no captures_g/residuals_g to plot (written '
                              'by another tool?)')
    if not (np.all(np.abs(captures) < 1e3) and np.all(np.abs(residuals) < 1e3)):
        raise FileFormatError(calibration_path, 'captures_g/residuals_g hold NaN, infinite '
                              'or absurd values (|value| >= 1000 g)')
    title = (f'{record.model} model, {data.get("positions")} positions, residual RMS '
             f'{float(data.get("residual_rms_g", float("nan"))) * 1e3:.2f} mg, predicted '
             f'roll/pitch p95 {record.predicted_tilt_error_deg:.3f} deg')
    plot_calibration(path, captures, residuals, record.sensor_model,
                     data.get('dropped_positions') or (), title)
