r"""
``accelcal study roi``: the false roll of the horizon inside a view panning across the sector.

Paper A, Fig. 6: a pitch error tilts the panorama's horizon into a wave; an operator
looking through a region of interest sees it as a horizon that *rolls* as the view pans
(and moves up or down). Here the five cameras of the horizon study
(:func:`.horizon_study.study_rig`, reference pitch 15 deg down, the paper's
``theta = -15 deg``) are rendered from the known scene with the true attitude; a levelled
view (:mod:`.view`) is built with an attitude off by ``+-2 deg`` of pitch (the paper's
case) and panned across the sector; in each view the horizon edge is found to sub-pixel
accuracy in every column and a line fitted: its angle is the false roll (degrees,
positive: the horizon's right end lower in the image) and its row at the centre column
minus the true horizon row ``c_y + f tan(el)`` the offset (pixels, positive down).

Closed form (checked against the rendering): with the attitude ``a_used`` while the body
is at ``a_true``, the true horizon is the great circle normal to
``n = R_bl(a_used) R_bl(a_true)^T e_z`` (level frame), ``n_P`` in the panorama frame; in
a view with ``R_PV`` the horizon is the image line ``m . [(u - c_x)/f, (v - c_y)/f, 1] = 0``
with ``m = R_PV^T n_P``: roll ``atan(-m_x / m_y)``, centre row ``c_y - f m_z / m_y``.
Finally the package's own calibration errors (K = 12 fits, as ``accelcal study horizon``)
give the false roll and offset across the azimuths by the closed form.
"""
import math
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rotation_from_rpy_radians
from accelcal_ros.panorama import render
from accelcal_ros.panorama.horizon_study import (PAPER_PITCH_DEG, REFERENCE_PITCH_RAD,
                                                 study_rig, tilt_errors_after_calibration)
from accelcal_ros.panorama.view import LevelledView, ViewMosaic
from accelcal_ros.panorama.view_pose import (horizon_row_px, view_camera_matrix,
                                             view_rotation, ViewPose)
import numpy as np
from numpy.typing import ArrayLike


def render_view_truth(scene: np.ndarray, width: int, height: int, pose: ViewPose,
                      imu_to_camera: ArrayLike = DEFAULT_IMU_TO_CAMERA) -> np.ndarray:
    """Return the scene's own pinhole view for ``pose`` (every pixel sampled straight)."""
    k = view_camera_matrix(width, height, pose.fov_h_rad)
    ys, xs = np.mgrid[0:height, 0:width].astype(float)
    rays = np.stack([(xs - k[0, 2]) / k[0, 0], (ys - k[1, 2]) / k[1, 1], np.ones_like(xs)], -1)
    in_panorama = rays @ view_rotation(pose.azimuth_rad, pose.elevation_rad).T
    to_level = render.panorama_frame_to_level(np.asarray(imu_to_camera, float).reshape(3, 3))
    return render.sample_scene(scene, in_panorama @ to_level.T)


def closed_form_horizon(width: int, height: int, pose: ViewPose,
                        true_roll_pitch: Tuple[float, float],
                        used_roll_pitch: Tuple[float, float],
                        imu_to_camera: ArrayLike = DEFAULT_IMU_TO_CAMERA
                        ) -> Tuple[float, float]:
    """Return ``(roll_deg, offset_px)`` of the true horizon in a view built wrongly."""
    normal_level = rotation_from_rpy_radians(*used_roll_pitch) @ \
        rotation_from_rpy_radians(*true_roll_pitch).T @ np.array([0.0, 0.0, 1.0])
    c = np.asarray(imu_to_camera, float).reshape(3, 3)
    n = render.panorama_frame_to_level(c).T @ normal_level
    m = view_rotation(pose.azimuth_rad, pose.elevation_rad).T @ n
    f = view_camera_matrix(width, height, pose.fov_h_rad)[0, 0]
    centre = (height - 1) / 2.0 - f * m[2] / m[1]
    return math.degrees(math.atan(-m[0] / m[1])), centre - horizon_row_px(height, width, pose)


class _Rows:
    """What :func:`render.horizon_rows` needs of a geometry, for a view image."""

    def __init__(self, height: int, row: float, focal: float) -> None:
        self.height, self._row, self._focal = height, row, focal

    def horizon_row(self) -> float:
        return self._row

    def pixels_per_radian_vertical(self) -> float:
        return self._focal


def measure_horizon(image: np.ndarray, view: LevelledView,
                    expected_row: Optional[float] = None) -> Tuple[float, float, float]:
    """
    Return ``(roll_deg, offset_px, fraction of columns)`` of the horizon edge in a view.

    The edge (the scene's sky/ground boundary, :func:`render.horizon_rows`) is searched
    3.5 deg around ``expected_row`` (default: the true horizon row); a line is fitted.
    """
    true_row = horizon_row_px(view.height, view.width, view.pose)
    row = true_row if expected_row is None else expected_row
    rows = render.horizon_rows(image, _Rows(view.height, row, view.camera_matrix[0, 0]),
                               search_deg=3.5, expected_row=row)
    cols = np.nonzero(np.isfinite(rows))[0]
    if cols.size < 10:
        return math.nan, math.nan, cols.size / max(1, image.shape[1])
    slope, intercept = np.polyfit(cols, rows[cols], 1)
    centre = intercept + slope * (view.width - 1) / 2.0
    return math.degrees(math.atan(slope)), float(centre - true_row), \
        cols.size / len(rows)


def run(count: int = 100, quick: bool = False, json_path: Optional[str] = None,
        say: Callable[[str], Any] = print,
        models: Optional[Sequence[Any]] = None) -> Dict[str, Any]:
    """Run the study; print the table with ``say``; return (and optionally write) it."""
    cam_w, cam_h = (640, 480) if quick else (1280, 960)
    width, height, fov = (640, 360, 60.0) if quick else (1280, 720, 60.0)
    azimuths = [-60.0, -30.0, 0.0, 30.0, 60.0] if quick else \
        [float(a) for a in range(-70, 71, 10)]
    rig = study_rig(cam_w, cam_h)
    scene = render.make_scene(3600, 1800, seed=1)
    true_att = (0.0, REFERENCE_PITCH_RAD)
    mosaic = ViewMosaic(rig)
    for i, image in enumerate(render.render_camera_views(scene, rig, *true_att)):
        mosaic.set_image(i, image)
    view = LevelledView(rig, mosaic.layout, width, height)
    say(f'roi study: 5 cameras {cam_w}x{cam_h}, reference pitch {PAPER_PITCH_DEG:g} deg '
        f'(paper sign), a {width}x{height} view of fov_h {fov:g} deg at elevation 0 panned '
        f'over azimuth {azimuths[0]:g}..{azimuths[-1]:g} deg')
    say('  roll: false roll of the horizon in the view (deg, + = right end lower); '
        'offset: horizon row minus the true one (px, + = down)')
    names = ('true attitude', 'pitch error -2 deg (paper)', 'pitch error +2 deg (paper)')
    say('  azimuth |' + ''.join(f' {name:^32} |' for name in names))
    say('          |' + '  roll  offset    (closed form)   |' * 3)
    cases = [('true', true_att)] + [
        (f'{e:+g}', (0.0, REFERENCE_PITCH_RAD - math.radians(e))) for e in (-2.0, 2.0)]
    table: List[Dict[str, Any]] = []
    for az in azimuths:
        pose = ViewPose.from_degrees(az, 0.0, fov)
        view.set_pose(pose)
        row: Dict[str, Any] = {'azimuth_deg': az}
        cells = []
        for name, used in cases:
            view.set_attitude(*used)
            image = view.render(mosaic.image)
            roll_cf, offset_cf = closed_form_horizon(width, height, pose, true_att, used)
            roll_m, offset_m, found = measure_horizon(image, view,
                                                      horizon_row_px(height, width, pose)
                                                      + offset_cf)
            row[name] = {'roll_deg': roll_m, 'offset_px': offset_m, 'columns': found,
                         'closed_form_roll_deg': roll_cf, 'closed_form_offset_px': offset_cf}
            cells.append(f' {roll_m:+6.3f} {offset_m:+7.2f} ({roll_cf:+6.3f} {offset_cf:+7.2f}) |')
        table.append(row)
        say(f'  {az:+7.1f} |' + ''.join(cells))
    results: Dict[str, Any] = {'view': {'width': width, 'height': height, 'fov_h_deg': fov},
                               'azimuths': table}
    for name in ('-2', '+2'):
        rolls = [abs(r[name]['roll_deg']) for r in table]
        offsets = [abs(r[name]['offset_px']) for r in table]
        say(f'  pitch error {name} deg: false roll up to {np.nanmax(rolls):.2f} deg, horizon '
            f'offset up to {np.nanmax(offsets):.1f} px across the sector')
    if models:
        roll_err, pitch_err = tilt_errors_after_calibration(models)
        worst_roll, worst_offset = [], []
        for r, p in zip(roll_err, pitch_err):
            used = (true_att[0] + r, true_att[1] + p)
            values = [closed_form_horizon(width, height, ViewPose.from_degrees(az, 0.0, fov),
                                          true_att, used) for az in azimuths]
            worst_roll.append(max(abs(v[0]) for v in values))
            worst_offset.append(max(abs(v[1]) for v in values))
        results['calibration'] = {
            'count': len(models),
            'false_roll_deg_median': float(np.median(worst_roll)),
            'false_roll_deg_p95': float(np.percentile(worst_roll, 95)),
            'offset_px_median': float(np.median(worst_offset)),
            'offset_px_p95': float(np.percentile(worst_offset, 95))}
        c = results['calibration']
        say(f'  own calibration ({len(models)} fits of 12 positions x 1 s): largest false roll '
            f'across the sector median {c["false_roll_deg_median"]:.4f} deg, 95 % '
            f'{c["false_roll_deg_p95"]:.4f} deg; horizon offset median '
            f'{c["offset_px_median"]:.2f} px, 95 % {c["offset_px_p95"]:.2f} px')
    if json_path:
        import json

        from accelcal_ros.fileio import write_text_atomic

        write_text_atomic(json_path, json.dumps(results, indent=1, default=float) + '\n')
        say(f'  table written to {json_path}')
    return results
