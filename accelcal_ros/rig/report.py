"""
What rig calibration writes: the rig file, the report (YAML) and the plot (PNG).

Rig file: the stitcher's format, written by :func:`accelcal_ros.camera.rig.save_rig`
(``cameras`` with ``name``, ``width``, ``height``, ``K``, ``D``, ``R`` = ``R_0i``,
reference first) with the top-level ``imu_to_camera`` (9 values row-major, IMU body ->
reference optical frame).
Report: per camera the intrinsics, their source, reprojection RMS and per-view errors;
per camera ``R_0i`` (rotation vector, optical axis azimuth/elevation in the reference
frame) with 1-sigma about the reference camera's x, y, z axes, ``t_0i`` and baseline;
``imu_to_camera`` with its 1-sigma, the board tilt, per-pose gravity errors, dropped
views and poses with the reason, warnings and timings.
"""
import os
import textwrap
from typing import Dict, List, Optional, Sequence

from accelcal_ros.camera import CameraModel
from accelcal_ros.camera.rig import Rig, rig_to_mapping, RigCamera
from accelcal_ros.errors import InputError
from accelcal_ros.fileio import refuse_overwriting_inputs, write_bytes_atomic, write_text_atomic
from accelcal_ros.rig.calibrate import RigCalibration
from accelcal_ros.textformats import dump_yaml
import numpy as np
from scipy.spatial.transform import Rotation


def _floats(values, digits: int = 9) -> list:
    return [float(round(float(v), digits)) + 0.0 for v in np.asarray(values).ravel()]


def rig_of(result: RigCalibration) -> Rig:
    """Return the calibrated rig (:class:`~accelcal_ros.camera.rig.Rig`), ``imu_to_camera`` too."""
    cams = []
    for i, name in enumerate(result.cameras):
        w, h = result.sizes[i]
        model = CameraModel(int(w), int(h), np.round(result.K[i], 6),
                            np.round(result.D[i][:5], 9))
        cams.append(RigCamera.from_model(name, model, result.fit.rotations[i],
                                         np.round(result.fit.translations_m[i], 6)))
    return Rig(tuple(cams), result.mount.imu_to_camera)


def _axis_deg(r: np.ndarray) -> list:
    axis = r[2]  # optical axis of camera i in the reference frame
    azimuth = np.degrees(np.arctan2(axis[0], axis[2]))
    elevation = np.degrees(np.arctan2(-axis[1], np.hypot(axis[0], axis[2])))
    return [round(float(azimuth), 4), round(float(elevation), 4)]


def report_mapping(result: RigCalibration) -> dict:
    """Return the report's mapping."""
    fit = result.fit
    cameras = {}
    for i, name in enumerate(result.cameras):
        intr = result.intrinsics[i]
        cameras[name] = {
            'intrinsics_source': intr.source,
            'K': _floats(result.K[i], 4), 'D': _floats(result.D[i][:5], 6),
            'fx_fy_cx_cy_std_px': _floats(fit.lens_std[i][:4], 4) if fit.lens_std else None,
            'views': int(fit.shared_views[i, i]),
            'image_coverage': round(result.coverage[i], 3),
            'zhang_rms_px': None if not np.isfinite(intr.rms_px) else round(intr.rms_px, 4),
            'rig_fit_view_rms_px': {p: round(e, 4) for (p, j), e in
                                    sorted(fit.view_rms_px.items()) if j == i},
            'R_0i_rotvec_deg': _floats(np.degrees(
                Rotation.from_matrix(fit.rotations[i]).as_rotvec()), 5),
            'axis_azimuth_elevation_deg': _axis_deg(fit.rotations[i]),
            'R_0i_std_deg_about_reference_xyz': _floats(fit.rotation_std_deg[i], 5),
            't_0i_m': _floats(fit.translations_m[i], 5),
            't_0i_std_m': _floats(fit.translation_std_m[i], 5),
            'baseline_m': round(float(np.linalg.norm(fit.translations_m[i])), 5),
        }
    pairs = {}
    for i in range(len(result.cameras)):
        for j in range(i + 1, len(result.cameras)):
            pairs[f'{result.cameras[i]}-{result.cameras[j]}'] = int(fit.shared_views[i, j])
    mount = result.mount
    return {
        'board': {'cols': result.board.cols, 'rows': result.board.rows,
                  'square_m': result.board.square_m},
        'reference': result.cameras[0],
        'rig_fit_rms_px': round(fit.rms_px, 5),
        'cameras': cameras,
        'shared_views': pairs,
        'imu_to_camera': {
            'R': _floats(mount.imu_to_camera, 9),
            'std_deg_about_reference_xyz': _floats(mount.std_deg, 5),
            'poses': len(mount.pose_error_deg),
            'pose_error_deg': {p: round(e, 5) for p, e in sorted(mount.pose_error_deg.items())},
            'heading_spread_deg': round(mount.heading_spread_deg, 1),
        },
        'board_tilt': {'estimated': mount.tilt_estimated,
                       'tilt_deg': round(mount.board_tilt_deg, 5),
                       'std_deg': round(mount.board_tilt_std_deg, 5),
                       'up_in_board_frame': _floats(mount.board_up, 7)},
        'no_board_in': list(result.no_board),
        'dropped_views': dict(sorted(result.dropped_views.items())),
        'dropped_poses': dict(sorted(result.dropped_poses.items())),
        'warnings': list(result.warnings),
        'fit_time_s': round(fit.fit_time_s, 3),
        'total_time_s': round(result.total_time_s, 3),
    }


def report_lines(result: RigCalibration) -> List[str]:
    """Return a short human summary, one string per line."""
    fit = result.fit
    lines = [f'rig calibration: {len(result.cameras)} cameras, reference {result.cameras[0]}, '
             f'rig fit RMS {fit.rms_px:.3f} px ({fit.fit_time_s:.2f} s)']
    for i, name in enumerate(result.cameras):
        k = result.K[i]
        std = fit.rotation_std_deg[i]
        az, el = _axis_deg(fit.rotations[i])
        lines.append(f'  {name}: f {k[0, 0]:.2f}/{k[1, 1]:.2f} px, c ({k[0, 2]:.2f}, '
                     f'{k[1, 2]:.2f}) px, {int(fit.shared_views[i, i])} views; axis az '
                     f'{az:.3f} el {el:.3f} deg, 1-sigma [{std[0]:.4f}, {std[1]:.4f}, '
                     f'{std[2]:.4f}] deg; baseline {np.linalg.norm(fit.translations_m[i]):.4f} m')
    m = result.mount
    lines.append(f'  imu_to_camera from {len(m.pose_error_deg)} poses: 1-sigma '
                 f'[{m.std_deg[0]:.4f}, {m.std_deg[1]:.4f}, {m.std_deg[2]:.4f}] deg, mean pose '
                 f'error {np.mean(list(m.pose_error_deg.values())):.4f} deg')
    if m.tilt_estimated:
        lines.append(f'  board tilt {m.board_tilt_deg:.3f} +- {m.board_tilt_std_deg:.3f} deg')
    else:
        lines.append('  board tilt not estimated (taken as level)')
    for key, why in sorted({**result.dropped_views, **result.dropped_poses}.items()):
        lines.append(f'  dropped {key}: {why}')
    for text in result.warnings:
        lines.append(f'  warning: {text}')
    return lines


def output_paths(path: str, cameras: Sequence[str]) -> List[str]:
    """
    Return every file :func:`write_outputs` writes for rig file ``path`` and ``cameras``.

    ``path``, ``<stem>_report.yaml``, ``<stem>.png`` and per camera
    ``<stem>_<camera>_camera_info.yaml`` (``<stem>``: ``path`` without ``.yaml``).
    """
    stem = path[:-5] if path.endswith('.yaml') else path
    return ([path, stem + '_report.yaml', stem + '.png']
            + [f'{stem}_{name}_camera_info.yaml' for name in cameras])


def check_outputs(path: str, cameras: Sequence[str], inputs: Sequence[Optional[str]],
                  export: Optional[str] = None) -> None:
    """
    Refuse now, before any work, what :func:`write_outputs` (and ``--export``) would fail on.

    Each output (the derived ones too) must be none of ``inputs`` nor inside an input
    directory, writable (no directory, device or FIFO there; a parent it can be made in)
    and distinct from the others. ``export`` (a capture directory to create) must not
    exist, must not lie inside an input and must not be one of the outputs.
    """
    from accelcal_ros.outputs import output_path_problem, parent_problem

    given = [p for p in inputs if p]
    paths = output_paths(path, cameras)
    seen: Dict[str, str] = {}
    for out in paths:
        refuse_overwriting_inputs(out, given)
        problem = output_path_problem(out)
        if problem:
            raise InputError(f'output {problem}')
        real = os.path.realpath(out)
        if real in seen:
            raise InputError(f'{out} would be written twice (also as {seen[real]}): camera '
                             'names and the rig file name collide; choose another -o')
        seen[real] = out
    if export is None:
        return
    if os.path.lexists(export):
        raise InputError(f'--export {export} exists; name a new folder')
    for item in given:
        item_real = os.path.realpath(item)
        export_real = os.path.realpath(export)
        if os.path.isdir(item_real) and (export_real + os.sep).startswith(
                item_real.rstrip(os.sep) + os.sep):
            raise InputError(f'--export {export} is inside {item}, an input of the command; '
                             'creating the capture there would change the input: choose a '
                             'folder outside it')
    if os.path.realpath(export) in seen:
        raise InputError(f'--export {export} is also an output file; name another folder')
    problem = parent_problem(export)
    if problem:
        raise InputError(f'--export {problem}')


def write_outputs(path: str, result: RigCalibration) -> List[str]:
    """
    Write the rig file, its report, plot and camera_info files; return their paths.

    ``<stem>_report.yaml``, ``<stem>.png`` and per camera ``<stem>_<camera>_camera_info.yaml``
    (camera_calibration_parsers YAML for a camera driver's ``camera_info_url``). Every
    file's content is made first, then each is written atomically: a failure while making
    them (the plot) writes nothing.
    """
    from accelcal_ros.camera.camera_info import camera_info_mapping

    rig = rig_of(result)
    paths = output_paths(path, [cam.name for cam in rig.cameras])
    texts = [dump_yaml(rig_to_mapping(rig)), dump_yaml(report_mapping(result))]
    png = plot_png(result)
    infos = [dump_yaml(camera_info_mapping(cam.name, cam.model)) for cam in rig.cameras]
    write_text_atomic(paths[0], texts[0])
    write_text_atomic(paths[1], texts[1])
    write_bytes_atomic(paths[2], png)
    for info_path, text in zip(paths[3:], infos):
        write_text_atomic(info_path, text)
    return paths


def _warning_text(warnings: List[str], width: int, most: int = 8) -> str:
    """Return the warnings wrapped to ``width`` characters, at most ``most`` of them."""
    lines = []
    for warning in warnings[:most]:
        lines += textwrap.wrap(warning, width, initial_indent='- ', subsequent_indent='  ')
    if len(warnings) > most:
        lines.append(f'... and {len(warnings) - most} more (see the report)')
    return '\n'.join(lines)


def plot(path: str, result: RigCalibration) -> None:
    """Write :func:`plot_png` to ``path`` (atomically)."""
    write_bytes_atomic(path, plot_png(result))


def plot_png(result: RigCalibration) -> bytes:
    """
    Draw one PNG of the calibration; return its bytes.

    Per camera the corners used (coverage) coloured by view error, the rig seen from
    above, and per pose the gravity error of ``imu_to_camera``.
    """
    import io

    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    n = len(result.cameras)
    cols = max(n, 3)   # the bottom row: rig, imu_to_camera, warnings (never over a plot)
    fig, axes = plt.subplots(2, cols, figsize=(4.2 * cols, 7.4), dpi=90)
    for unused in axes[0, n:]:
        unused.axis('off')
    fit = result.fit
    for i, name in enumerate(result.cameras):
        ax = axes[0, i]
        w, h = result.sizes[i]
        for (pose, j), corners in sorted(result.detections.items()):
            if j != i:
                continue
            err = fit.view_rms_px.get((pose, j), np.nan)
            ax.scatter(corners[:, 0], corners[:, 1], s=2,
                       c=[[min(1.0, err / 0.5), 0.2, 1.0 - min(1.0, err / 0.5)]])
        ax.set_xlim(0, w)
        ax.set_ylim(h, 0)
        ax.set_aspect('equal')
        std = fit.rotation_std_deg[i]
        ax.set_title(f'{name}: {int(fit.shared_views[i, i])} views, cover '
                     f'{100 * result.coverage[i]:.0f} %\nR_0i 1-sigma '
                     f'{np.max(std):.3f} deg', fontsize=9)
    ax = axes[1, 0]
    for i, name in enumerate(result.cameras):
        axis = fit.rotations[i][2]
        centre = -fit.rotations[i].T @ fit.translations_m[i]
        ax.arrow(centre[0], centre[2], 0.1 * axis[0], 0.1 * axis[2], width=0.002,
                 color=f'C{i}')
        ax.annotate(name, (centre[0] + 0.11 * axis[0], centre[2] + 0.11 * axis[2]), fontsize=8)
    ax.set_aspect('equal')
    ax.set_xlim(-0.2, 0.2)
    ax.set_ylim(-0.1, 0.2)
    ax.set_xlabel('x right (m, reference camera)')
    ax.set_ylabel('z forward (m)')
    ax.set_title('rig from above (optical axes)', fontsize=9)
    ax = axes[1, 1]
    errors = result.mount.pose_error_deg
    ax.bar(range(len(errors)), list(errors.values()))
    ax.set_xticks(range(len(errors)))
    ax.set_xticklabels([p.replace('pose', '') for p in errors], fontsize=6, rotation=90)
    ax.set_ylabel('angle(C f, board up) [deg]')
    m = result.mount
    ax.set_title(f'imu_to_camera: 1-sigma {np.max(m.std_deg):.3f} deg, board tilt '
                 f'{m.board_tilt_deg:.2f} deg', fontsize=9)
    for extra in axes[1, 2:]:
        extra.axis('off')
    if result.warnings:
        axes[1, 2].text(0, 1, _warning_text(result.warnings, 55 * (cols - 2)), va='top',
                        fontsize=7, transform=axes[1, 2].transAxes, clip_on=False)
    fig.tight_layout()
    buffer = io.BytesIO()
    try:
        fig.savefig(buffer, format='png')
    finally:
        plt.close(fig)
    return buffer.getvalue()
