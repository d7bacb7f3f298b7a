r"""
The horizon of stitched panoramas, measured: sub-pixel rows, tilt fit, errors along a drive.

Ground truth for the attitude a panorama was levelled with. A scene of
:func:`~.render.make_scene` has a sharp sky/ground edge at elevation 0 between uniform
bands; in a panorama stitched with the true attitude it lies on the geometry's horizon row,
with an erroneous one on a tilted great circle.

* :func:`edge_rows`: the edge's row in every column by the *area* method: within a window
  of rows around a first guess, the sky fraction ``s = (grey - ground) / (sky - ground)``
  summed over the window gives the edge position. Bilinear resampling (the renderer's and
  the stitcher's) conserves that sum, so the estimate moves exactly with the edge (no
  pixel-phase ripple, unlike a threshold crossing); 8-bit rounding leaves ~0.005 px.
* :func:`fit_horizon_tilt`: a tilted great circle seen in the panorama frame satisfies
  ``tan(el) = a cos(az) + b sin(az)``; the least-squares ``(a, b)`` over the measured
  columns give the horizon's offset at the centre column (``atan a``, pitch-like), its
  slope there (``atan b``, roll-like), and the tilt ``atan(hypot(a, b))`` (the largest
  displacement over a full turn).
* :func:`drive_horizon_errors`: ``accelcal study motion``'s end-to-end figure. Camera
  images of the scene rendered with the drive's *true* attitude at each frame time are
  stitched with each aid's *estimated* attitude (the package's
  :class:`~.stitch.Stitcher`), and the horizon is compared with the panorama stitched
  with the true attitude. Plain arrays in, plain arrays out (the attitude feature computes
  the estimates; the ``accelcal`` dispatcher combines both).
"""
import math
from typing import Any, Dict, Mapping, Optional, Tuple

from accelcal_ros.camera.rig import Rig, ring_rig
from accelcal_ros.errors import InputError
from accelcal_ros.panorama import render
from accelcal_ros.panorama.projection import PanoramaGeometry
from accelcal_ros.panorama.rig_projection import normalized_from_pixels
import numpy as np
from numpy.typing import ArrayLike

FOCAL_EQUIVALENT_PX = 1100.0
"""Focal length (px) the pixel figures are also expressed at (the issue's reference)."""
SCENE_BAND_DEG = 30.0
"""Uniform sky/ground bands of the drive study's scene (larger than any tilt error)."""


def _levels() -> Tuple[float, float]:
    return float(np.mean(render.SKY_BGR)), float(np.mean(render.GROUND_BGR))


def edge_rows(panorama: np.ndarray, guess_rows: ArrayLike, half_window_px: int = 6,
              sky_grey: Optional[float] = None,
              ground_grey: Optional[float] = None) -> np.ndarray:
    """
    Return the sky/ground edge's continuous row in every column (NaN where not measurable).

    ``guess_rows``: a first guess per column (or one for all; NaN: skip the column). The
    window is the ``2 * half_window_px + 1`` rows around it; a column counts only where the
    window lies inside the image, its top is sky and its bottom ground (within 15 % of the
    contrast), and nothing in it is uncovered (black). Grey levels default to the colours
    of :func:`~.render.make_scene`.
    """
    grey = np.asarray(panorama, dtype=np.float32)
    if grey.ndim == 3:
        grey = grey.mean(axis=2)
    height, width = grey.shape
    sky_default, ground_default = _levels()
    sky = sky_default if sky_grey is None else float(sky_grey)
    ground = ground_default if ground_grey is None else float(ground_grey)
    if not sky > ground:
        raise InputError(f'sky grey ({sky}) must be brighter than ground grey ({ground})')
    guess = np.broadcast_to(np.asarray(guess_rows, dtype=float), (width,))
    known = np.isfinite(guess)
    centre = np.where(known, np.rint(np.where(known, guess, 0.0)), 0).astype(int)
    top = centre - half_window_px
    span = 2 * half_window_px + 1
    inside = known & (top >= 0) & (top + span <= height)
    rows = np.clip(top[None, :] + np.arange(span)[:, None], 0, height - 1)
    window = grey[rows, np.arange(width)[None, :]]
    fraction = (window - ground) / (sky - ground)
    margin = 0.15
    valid = inside & (np.abs(fraction[0] - 1.0) < margin) & (np.abs(fraction[-1]) < margin)
    valid &= np.all(window > 0.5 * ground, axis=0)
    # sky rows above the edge: the sum of the clipped sky fraction; the edge lies between
    # the last sky row and the first ground row, i.e. at top - 0.5 + that sum
    position = top - 0.5 + np.clip(fraction, 0.0, 1.0).sum(axis=0)
    return np.where(valid, position, np.nan)


def horizon_rows_fine(panorama: np.ndarray, geometry: PanoramaGeometry,
                      search_deg: float = 3.5, half_window_px: int = 6) -> np.ndarray:
    """
    Return the horizon's row per column: a sky-to-ground crossing refined by :func:`edge_rows`.

    The crossing (grey level midway between sky and ground, with covered pixels on both
    sides) is looked for within ``search_deg`` of the geometry's horizon row; the first
    from the top counts. Uncovered (black) rows may lie anywhere around it.
    """
    grey = np.asarray(panorama, dtype=np.float32)
    if grey.ndim == 3:
        grey = grey.mean(axis=2)
    sky, ground = _levels()
    threshold = 0.5 * (sky + ground)
    centre = geometry.horizon_row()
    reach = int(np.ceil(np.radians(search_deg) * geometry.pixels_per_radian_vertical()))
    r0 = max(0, int(np.floor(centre)) - reach)
    r1 = min(geometry.height, int(np.ceil(centre)) + reach + 1)
    window = grey[r0:r1]
    crossing = (window[:-1] >= threshold) & (window[1:] < threshold) \
        & (window[1:] > 0.5 * ground)
    found = crossing.any(axis=0)
    first = np.argmax(crossing, axis=0)
    guess = np.where(found, r0 + first + 0.5, np.nan)
    return edge_rows(grey, guess, half_window_px)


def fit_horizon_tilt(rows: ArrayLike, geometry: PanoramaGeometry,
                     min_columns: int = 20) -> Tuple[float, float, float]:
    """
    Fit ``tan(el) = a cos(az) + b sin(az)`` to a horizon's rows; return ``(a, b, rms_px)``.

    ``rows``: one continuous row per column (NaN: not seen). ``a`` is the tangent of the
    horizon's elevation at the centre column, ``b`` that of its slope there; ``rms_px``
    the residual (rows). Raises :class:`InputError` with fewer than ``min_columns``
    measured columns or columns spanning less than 10 deg of azimuth.
    """
    r = np.asarray(rows, dtype=float).reshape(-1)
    if r.size != geometry.width:
        raise InputError(f'expected {geometry.width} rows (one per column), got {r.size}')
    ok = np.isfinite(r)
    az = geometry.azimuth_rad(np.arange(geometry.width))[ok]
    if ok.sum() < min_columns or np.ptp(az) < math.radians(10.0):
        raise InputError(f'horizon seen in {int(ok.sum())} columns over '
                         f'{math.degrees(np.ptp(az)) if az.size else 0.0:.1f} deg of azimuth: '
                         f'too few to fit its tilt (need {min_columns} over 10 deg)')
    tan_el = np.tan(geometry.elevation_rad(r[ok]))
    design = np.stack([np.cos(az), np.sin(az)], axis=1)
    (a, b), *_ = np.linalg.lstsq(design, tan_el, rcond=None)
    model = geometry.row_from_elevation(np.arctan(design @ np.array([a, b])))
    return float(a), float(b), float(np.sqrt(np.mean((model - r[ok]) ** 2)))


def tilt_between_deg(true_rp: ArrayLike, used_rp: ArrayLike) -> np.ndarray:
    """Return the angle (deg) between the true and the used "up" of ``(N, 2)`` roll/pitch."""
    def up(rp: np.ndarray) -> np.ndarray:
        roll, pitch = rp[:, 0], rp[:, 1]
        return np.stack([-np.sin(pitch), np.cos(pitch) * np.sin(roll),
                         np.cos(pitch) * np.cos(roll)], axis=1)

    t = np.asarray(true_rp, dtype=float).reshape(-1, 2)
    u = np.asarray(used_rp, dtype=float).reshape(-1, 2)
    cosine = np.clip(np.sum(up(t) * up(u), axis=1), -1.0, 1.0)
    return np.degrees(np.arccos(cosine))


def _angle_between(u: Tuple[float, ...], v: Tuple[float, ...]) -> float:
    cosine = np.dot(u, v) / (np.linalg.norm(u) * np.linalg.norm(v))
    return float(np.arccos(np.clip(cosine, -1.0, 1.0)))


class HorizonBench:
    """
    A small rig, a horizon scene and a stitcher: panoramas of known truth, measured.

    ``camera_width`` x 3/4 px cameras (the horizon study's 5-camera ring, f scaled); the
    panorama is the 180 x 120 deg sector at the cameras' resolution. Rays of every
    camera pixel are computed once, so rendering a frame is one matrix product and one
    ``cv2.remap`` per camera.
    """

    def __init__(self, camera_width: int = 160, band_deg: float = SCENE_BAND_DEG,
                 rig: Optional[Rig] = None, scene_width: int = 1800) -> None:
        from accelcal_ros.panorama.stitch import Stitcher

        if rig is None:
            height = camera_width * 3 // 4
            rig = ring_rig(5, camera_width, height, 1100.0 * camera_width / 1280.0, 36.0,
                           distortion=(-0.05, 0.01, 0.0, 0.0, 0.0), mount_error_deg=0.3,
                           seed=4)
        self.rig = rig
        focal = float(rig.cameras[0].K[0, 0])
        width = int(round(math.pi * focal)) // 2 * 2
        self.geometry = PanoramaGeometry(width, width * 2 // 3, 180.0, 120.0, 'spherical')
        self.px_per_rad = float(self.geometry.pixels_per_radian_vertical())
        self.scene = render.make_scene(scene_width, scene_width // 2, seed=1,
                                       band_deg=band_deg)
        self.search_deg = band_deg - 2.0
        self.stitcher = Stitcher(rig, self.geometry, rebuild_threshold_deg=0.0)
        self._rays = []
        for cam in rig.cameras:
            ys, xs = np.mgrid[0:cam.height, 0:cam.width].astype(np.float64)
            xn, yn = normalized_from_pixels(cam, xs, ys)
            self._rays.append(np.stack([xn, yn, np.ones_like(xn)], axis=-1))

    def views(self, roll: float, pitch: float) -> list:
        """Render every camera's image for the true body attitude (rad)."""
        return [render.sample_scene(self.scene, rays @ render.camera_to_level(
            self.rig, i, roll, pitch).T) for i, rays in enumerate(self._rays)]

    def horizon(self, views: list, roll: float, pitch: float) -> np.ndarray:
        """Stitch ``views`` with the attitude ``(roll, pitch)`` (rad); return its rows."""
        panorama = self.stitcher.stitch(views, roll, pitch)
        return horizon_rows_fine(panorama, self.geometry, self.search_deg)

    def measure(self, rows: np.ndarray, reference_rows: np.ndarray) -> Dict[str, float]:
        """Compare a panorama's horizon with the true-attitude panorama's (px, deg)."""
        a, b, _ = fit_horizon_tilt(rows, self.geometry)
        a0, b0, _ = fit_horizon_tilt(reference_rows, self.geometry)
        both = np.isfinite(rows) & np.isfinite(reference_rows)
        deviation = float(np.max(np.abs(rows[both] - reference_rows[both]))) if both.any() \
            else float('nan')
        return {'deviation_px': deviation,
                'offset_px': self.px_per_rad * (math.atan(a) - math.atan(a0)),
                'roll_deg': math.degrees(math.atan(b) - math.atan(b0)),
                'tilt_px': self.px_per_rad * _angle_between((a, b, 1.0), (a0, b0, 1.0))}


def drive_horizon_errors(true_rp: ArrayLike, estimates: Mapping[str, ArrayLike],
                         camera_width: int = 160,
                         progress: Any = None) -> Dict[str, Any]:
    """
    Stitch each frame with each estimate; return the horizon errors against the truth.

    ``true_rp``: ``(N, 2)`` true roll/pitch (rad) at the frame times; ``estimates``:
    ``{name: (N, 2)}`` the attitude each aid would stitch that frame with. Returns
    ``{'px_per_rad', 'geometry', 'frames', 'aids': {name: {'deviation_px', 'offset_px',
    'roll_deg', 'tilt_px', 'closed_form_px'}}}``, arrays of N (NaN where the horizon was
    not seen well enough); ``deviation_px`` is the largest row difference over the columns
    both panoramas see, ``closed_form_px`` ``px_per_rad * err`` of the tilt error.
    ``progress(iterable, label)`` may wrap the frame loop.
    """
    truth = np.asarray(true_rp, dtype=float).reshape(-1, 2)
    est = {name: np.asarray(v, dtype=float).reshape(-1, 2) for name, v in estimates.items()}
    for name, values in est.items():
        if values.shape != truth.shape:
            raise InputError(f'estimate {name!r}: {values.shape[0]} frames, the truth has '
                             f'{truth.shape[0]}')
    bench = HorizonBench(camera_width)
    keys = ('deviation_px', 'offset_px', 'roll_deg', 'tilt_px')
    out = {name: {k: np.full(len(truth), np.nan) for k in keys} for name in est}
    frames = range(len(truth))
    if progress is not None:
        frames = progress(frames, 'panorama horizon: stitching')
    for k in frames:
        roll, pitch = truth[k]
        views = bench.views(roll, pitch)
        reference = bench.horizon(views, roll, pitch)
        for name, values in est.items():
            if not np.all(np.isfinite(values[k])):
                continue
            rows = bench.horizon(views, *values[k])
            try:
                figures = bench.measure(rows, reference)
            except InputError:
                continue
            for key in keys:
                out[name][key][k] = figures[key]
    for name, values in est.items():
        out[name]['closed_form_px'] = bench.px_per_rad * np.radians(
            tilt_between_deg(truth, values))
    return {'px_per_rad': bench.px_per_rad, 'geometry': bench.geometry,
            'frames': len(truth), 'aids': out}


def format_drive_horizon(result: Mapping[str, Any], label: str = '') -> list:
    """Return the aligned table of :func:`drive_horizon_errors` (px and px at f = 1100)."""
    geometry = result['geometry']
    scale = FOCAL_EQUIVALENT_PX / result['px_per_rad']
    lines = [f'Panorama horizon through the drive{label}: {result["frames"]} frames stitched '
             "with each aid's attitude, measured against the true-attitude panorama "
             f'({geometry.width}x{geometry.height} px sector, {result["px_per_rad"]:.1f} '
             'px/rad)',
             '  largest horizon deviation (px, and at f = '
             f'{FOCAL_EQUIVALENT_PX:g} px), centre-column offset (px) and horizon roll p95; '
             'closed form: px/rad x tilt error',
             f'{"estimator":<20} {"p50":>6} {"p95":>6} {"max":>6} | {"@1100 p50":>9} '
             f'{"p95":>6} {"max":>6} | {"offset p95":>10} {"roll p95 deg":>12} | '
             f'{"closed form p95":>15}']
    for name, figures in result['aids'].items():
        dev = figures['deviation_px']
        dev = dev[np.isfinite(dev)]
        if not dev.size:
            lines.append(f'{name:<20} horizon not measurable')
            continue
        p50, p95, worst = np.percentile(dev, [50, 95, 100])
        offset = np.nanpercentile(np.abs(figures['offset_px']), 95)
        roll = np.nanpercentile(np.abs(figures['roll_deg']), 95)
        closed = np.nanpercentile(figures['closed_form_px'], 95)
        lines.append(f'{name:<20} {p50:6.2f} {p95:6.2f} {worst:6.2f} | {p50 * scale:9.2f} '
                     f'{p95 * scale:6.2f} {worst * scale:6.2f} | {offset:10.2f} '
                     f'{roll:12.3f} | {closed:15.2f}')
    return lines
