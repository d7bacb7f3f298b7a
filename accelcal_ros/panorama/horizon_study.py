r"""
``accelcal study horizon``: paper A's Fig. 6 experiment on a rendered scene.

Paper A (Sect. "Results of the semi-natural experiment"): five calibrated cameras, the
reference camera at pitch ``theta = -15 deg``, a spherical sector of 180 x 120 deg at
3600 x 2400 px; pitch errors of -2 and +2 deg move the horizon by up to 36 and 28 px.

Sign: the paper's pitch is positive nose-up (its eq. 3 applied to its own ``g``), REP-103's
positive nose-down, so the paper's ``theta = -15 deg`` is REP-103 pitch +15 deg (cameras
looking 15 deg down at the terrain) and its ``Delta theta = -2 deg`` is a REP-103 pitch
error of +2 deg. Both signs are reported with the paper's labels.

Here the five camera views are rendered from a known equirectangular scene
(:mod:`.render`) with the true attitude, stitched with the true and with the erroneous
attitude, and the horizon (a sharp sky/ground edge) is located to sub-pixel accuracy in
every column; the figure is the largest deviation over the columns where the horizon is
seen. It is checked against the closed form: a panorama built with attitude ``a_used``
shows the true horizon where ``n . M = 0`` with ``n = R_bl(a_used) R_bl(a_true)^T e_z``
expressed in the panorama frame, i.e. ``tan el = (n_x sin az + n_z cos az) / n_y``.

Finally the package's own calibration error is injected: ``count`` calibrations fitted
by the package (:func:`accelcal_ros.calibration.study.fitted_models`, 12 positions,
1 s each) give, at the reference attitude, ``truth.distort(f) -> est.correct -> roll,
pitch`` errors, whose horizon deviations are computed with the closed form.
"""
import math
from typing import Any, Callable, Dict, Optional, Sequence, Tuple

from accelcal_ros.camera.rig import Rig, ring_rig
from accelcal_ros.frames import (DEFAULT_IMU_TO_CAMERA, roll_pitch_from_specific_force,
                                 rotation_from_rpy_radians, specific_force_from_roll_pitch)
from accelcal_ros.panorama import render
from accelcal_ros.panorama.projection import PanoramaGeometry
from accelcal_ros.recording.progress import track
import numpy as np

PAPER_PITCH_DEG = -15.0
"""Reference camera pitch in the paper (its sign: nose-up positive)."""
REFERENCE_PITCH_RAD = math.radians(-PAPER_PITCH_DEG)
"""The same attitude in REP-103 (nose-down positive): +15 deg."""
PAPER_DEVIATION_PX = {-2.0: 36.0, 2.0: 28.0}
"""Paper A, Fig. 6 b/c: largest horizon deviation (px) for pitch errors -2 / +2 deg."""


def study_rig(width: int = 1280, height: int = 960) -> Rig:
    """Return the study's rig: 5 cameras, 60 deg horizontal FOV, 36 deg apart, mild lens."""
    focal = 1100.0 * width / 1280.0
    return ring_rig(5, width, height, focal, 36.0, distortion=(-0.05, 0.01, 0.0, 0.0, 0.0),
                    mount_error_deg=0.3, seed=4)


def analytic_horizon_rows(geometry: PanoramaGeometry, true_roll_pitch: Tuple[float, float],
                          used_roll_pitch: Tuple[float, float],
                          imu_to_camera: np.ndarray = DEFAULT_IMU_TO_CAMERA) -> np.ndarray:
    """
    Return the row of the true horizon in every column of a panorama built wrongly.

    The panorama is built with the attitude ``used_roll_pitch`` while the body is at
    ``true_roll_pitch`` (radians); rows are continuous (pixel centres at integers).
    """
    true_r = rotation_from_rpy_radians(*true_roll_pitch)
    used_r = rotation_from_rpy_radians(*used_roll_pitch)
    normal_level = used_r @ true_r.T @ np.array([0.0, 0.0, 1.0])
    n = render.panorama_frame_to_level(imu_to_camera).T @ normal_level
    az = geometry.azimuth_rad(np.arange(geometry.width))
    elevation = np.arctan2(n[0] * np.sin(az) + n[2] * np.cos(az), n[1])
    elevation = (elevation + np.pi / 2) % np.pi - np.pi / 2
    return geometry.row_from_elevation(elevation)


def tilt_errors_after_calibration(models: Sequence[Any], truth: Any = None, roll: float = 0.0,
                                  pitch: float = REFERENCE_PITCH_RAD) -> np.ndarray:
    """Return ``(roll_error, pitch_error)`` arrays (rad) of each fitted model at an attitude."""
    from accelcal_ros.sensor.model import paper_a_model

    truth = paper_a_model(500) if truth is None else truth
    force = specific_force_from_roll_pitch(roll, pitch)
    raw = truth.distort(force)
    errors = []
    for model in models:
        est_roll, est_pitch = roll_pitch_from_specific_force(model.correct(raw))
        errors.append((float(est_roll) - roll, float(est_pitch) - pitch))
    return np.array(errors).reshape(-1, 2).T


def run(width: int = 3600, height: int = 2400, count: int = 100, quick: bool = False,
        out_dir: Optional[str] = None, say: Callable[[str], Any] = print,
        models: Optional[Sequence[Any]] = None) -> Dict[str, Any]:
    """
    Run the study; print a readable table with ``say`` and return the figures as a dict.

    ``models`` (a list of SensorModel): the package's own calibrations for the last row
    (``accelcal study horizon`` passes K = 12 fits from the calibration feature; the row is
    left out when None).
    """
    from accelcal_ros.fileio import write_bytes_atomic
    from accelcal_ros.panorama.stitch import Stitcher
    import cv2

    if quick:
        width, height, count = width // 2, height // 2, min(count, 20)
    geometry = PanoramaGeometry(width, height, 180.0, 120.0, 'spherical')
    cam_w, cam_h = (1280, 960) if not quick else (640, 480)
    rig = study_rig(cam_w, cam_h)
    scene = render.make_scene(3600, 1800, seed=1)
    true_att = (0.0, REFERENCE_PITCH_RAD)
    views = render.render_camera_views(scene, rig, *true_att)
    stitcher = Stitcher(rig, geometry)
    ppd = geometry.pixels_per_radian_vertical() * math.pi / 180.0
    say(f'horizon study: 5 cameras {cam_w}x{cam_h}, sector 180 x 120 deg at '
        f'{width} x {height} px ({ppd:.1f} px/deg), reference pitch {PAPER_PITCH_DEG:g} deg '
        f'(paper sign; REP-103 {math.degrees(REFERENCE_PITCH_RAD):+g} deg)')
    truth_pano = stitcher.stitch(views, *true_att)
    seen = stitcher.coverage()
    truth_rows = render.horizon_rows(truth_pano, geometry)
    centre = geometry.horizon_row()
    ok = np.isfinite(truth_rows)
    columns = ok
    say(f'  true attitude: horizon found in {int(ok.sum())} of {width} columns, row '
        f'{np.nanmean(truth_rows):.2f} (expected {centre:.1f}), largest offset '
        f'{np.nanmax(np.abs(truth_rows - centre)):.2f} px')
    rows_by_error: Dict[float, Dict[str, float]] = {}
    results: Dict[str, Any] = {
        'geometry': geometry, 'truth_offset_px': float(np.nanmax(np.abs(truth_rows - centre))),
        'columns_seen': int(ok.sum()), 'rows': rows_by_error}
    images = {'true': truth_pano}
    say('  pitch error (paper sign) | max horizon deviation: rendered | closed form | paper')
    for paper_error_deg in track((-2.0, 2.0), 'horizon study: stitching'):
        used = (0.0, REFERENCE_PITCH_RAD - math.radians(paper_error_deg))
        pano = stitcher.stitch(views, *used)
        expected = analytic_horizon_rows(geometry, true_att, used)
        rows = render.horizon_rows(pano, geometry, search_deg=3.5)
        both = np.isfinite(rows) & columns
        measured = float(np.max(np.abs(rows[both] - truth_rows[both]))) if both.any() \
            else float('nan')
        closed = float(np.max(np.abs(expected[columns] - centre)))
        agreement = float(np.max(np.abs(rows[both] - expected[both]))) if both.any() \
            else float('nan')
        rows_by_error[paper_error_deg] = {'rendered_px': measured, 'closed_form_px': closed,
                                          'model_misfit_px': agreement,
                                          'paper_px': PAPER_DEVIATION_PX[paper_error_deg]}
        images[f'pitch_error_{paper_error_deg:+g}deg'] = pano
        say(f'  {paper_error_deg:+5.1f} deg                 | {measured:7.1f} px       | '
            f'{closed:7.1f} px   | {PAPER_DEVIATION_PX[paper_error_deg]:4.0f} px   '
            f'(rendered vs closed form within {agreement:.2f} px)')
    say('  the closed form gives delta_pitch x px/deg at the reference heading (az = 0); '
        'the paper measured its real rig by eye, over the horizon it could see')
    if models:
        roll_err, pitch_err = tilt_errors_after_calibration(models)
        deviations = np.array([np.max(np.abs(analytic_horizon_rows(
            geometry, true_att, (true_att[0] + r, true_att[1] + p))[columns] - centre))
            for r, p in zip(roll_err, pitch_err)])
        tilt = np.degrees(np.hypot(roll_err, pitch_err))
        results['calibration'] = {
            'count': len(models), 'tilt_error_deg_median': float(np.median(tilt)),
            'tilt_error_deg_p95': float(np.percentile(tilt, 95)),
            'deviation_px_median': float(np.median(deviations)),
            'deviation_px_p95': float(np.percentile(deviations, 95)),
            'deviation_px_max': float(np.max(deviations))}
        c = results['calibration']
        say(f'  own calibration (12 positions x 1 s, {len(models)} fits): tilt error median '
            f'{c["tilt_error_deg_median"]:.3f} deg, 95 % {c["tilt_error_deg_p95"]:.3f} deg -> '
            f'horizon deviation median {c["deviation_px_median"]:.2f} px, 95 % '
            f'{c["deviation_px_p95"]:.2f} px, max {c["deviation_px_max"]:.2f} px')
    if out_dir:
        import os

        for name, image in images.items():
            ok_png, data = cv2.imencode('.png', image)
            write_bytes_atomic(os.path.join(out_dir, f'horizon_{name}.png'), data.tobytes())
        say(f'  panoramas written to {out_dir}/horizon_*.png')
    results['seen_fraction'] = float(seen.mean())
    return results
