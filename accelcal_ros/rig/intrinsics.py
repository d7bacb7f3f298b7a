"""
Per-camera intrinsics: ``K`` and OpenCV distortion from board views, or a camera_info file.

Zhang's method through ``cv2.calibrateCameraExtended`` (the model ``k1, k2, p1, p2``;
``k3`` fixed at 0 unless asked, as OpenCV advises for ordinary lenses). Pixel
coordinates follow OpenCV: integer values at pixel centres. A view whose reprojection
RMS exceeds ``max(min_drop_px, drop_factor x median)`` is dropped with the reason and
the camera is calibrated again without it.

``--intrinsics`` files are the YAML that ROS's camera_calibration writes
(``image_width``, ``image_height``, ``camera_name``, ``camera_matrix: {rows, cols, data}``,
``distortion_model: plumb_bob``, ``distortion_coefficients: {data}``).
"""
from dataclasses import dataclass, field
from typing import Dict, List, Sequence, Tuple, TypeVar

from accelcal_ros.errors import CalibrationError, FileFormatError
import cv2
import numpy as np

Key = TypeVar('Key')

MIN_VIEWS = 4


@dataclass
class Intrinsics:
    """``K`` (3x3, px), ``D`` (5 or 8), the view errors (px RMS per view id) and the drops."""

    K: np.ndarray
    D: np.ndarray
    size: Tuple[int, int]
    rms_px: float = float('nan')
    view_rms_px: Dict[str, float] = field(default_factory=dict)
    dropped: Dict[str, str] = field(default_factory=dict)
    source: str = 'board views'


def views_over_limit(errors: Sequence[Tuple[Key, float]], min_px: float, factor: float
                     ) -> Tuple[float, List[Tuple[Key, float]]]:
    """
    Return ``(limit, [(view, rms) above it])``: the views a fit drops and iterates without.

    ``errors`` pairs each view with its reprojection RMS (px); the limit is the larger of
    ``min_px`` and ``factor`` times the median RMS (intrinsics and the rig fit alike).
    """
    limit = max(min_px, factor * float(np.median([e for _, e in errors])))
    return limit, [(view, e) for view, e in errors if e > limit]


def view_rms(object_points: np.ndarray, corners: np.ndarray, k: np.ndarray,
             d: np.ndarray) -> Tuple[float, np.ndarray, np.ndarray]:
    """Return ``(rms_px, rvec, tvec)`` of one view under fixed intrinsics (solvePnP)."""
    ok, rvec, tvec = cv2.solvePnP(object_points, corners, k, d, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        ok, rvec, tvec = cv2.solvePnP(object_points, corners, k, d)
    rvec, tvec = cv2.solvePnPRefineLM(object_points, corners, k, d, rvec, tvec)
    px, _ = cv2.projectPoints(object_points, rvec, tvec, k, d)
    err = np.linalg.norm(px.reshape(-1, 2) - corners, axis=1)
    return float(np.sqrt(np.mean(err ** 2))), rvec.ravel(), tvec.ravel()


def calibrate_camera(name: str, views: Dict[str, np.ndarray], object_points: np.ndarray,
                     size: Tuple[int, int], fix_k3: bool = True, min_drop_px: float = 0.5,
                     drop_factor: float = 4.0) -> Intrinsics:
    """
    Calibrate one camera from its views ``{view id: corners (N, 2)}`` (board-frame order).

    Raises :class:`CalibrationError` when fewer than 4 usable views remain.
    """
    ids = sorted(views)
    dropped: Dict[str, str] = {}
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    obj = object_points.astype(np.float32)
    for _ in range(3):
        if len(ids) < MIN_VIEWS:
            raise CalibrationError(
                f'camera {name}: only {len(ids)} usable board view(s), need at least '
                f'{MIN_VIEWS} for its intrinsics: add poses where {name} sees the whole board '
                '(near the image corners and tilted), or give --intrinsics for it')
        # the stubs do not allow None for the initial camera matrix / distortion (OpenCV does)
        result = cv2.calibrateCameraExtended(  # type: ignore[call-overload]
            [obj] * len(ids), [views[i].astype(np.float32) for i in ids], tuple(size),
            None, None, flags=flags)
        rms, k, d, _, _, _, _, per_view = result
        per_view = np.asarray(per_view, dtype=float).ravel()
        limit, bad = views_over_limit(list(zip(ids, per_view)), min_drop_px, drop_factor)
        if not bad:
            break
        for i, e in bad:
            dropped[i] = (f'reprojection RMS {e:.2f} px > {limit:.2f} px (blurred, moved or '
                          'a wrong corner)')
        ids = [i for i in ids if i not in dropped]
    d5 = np.zeros(5)
    d5[:min(5, np.size(d))] = np.ravel(d)[:5]
    if not np.all(np.isfinite(k)) or not np.all(np.isfinite(d5)):
        raise CalibrationError(f'camera {name}: calibration diverged; check the board size '
                               'and square, or give --intrinsics for it')
    return Intrinsics(np.asarray(k, dtype=float), d5, (int(size[0]), int(size[1])), float(rms),
                      {i: float(e) for i, e in zip(ids, per_view)}, dropped)


def load_camera_info(path: str) -> Tuple[str, Intrinsics]:
    """Read a camera_calibration YAML; return ``(camera_name, Intrinsics)``."""
    from accelcal_ros.camera.camera_info import load_camera_info as load_file

    name, model = load_file(path)
    if model.is_fisheye:
        raise FileFormatError(path, 'equidistant (fisheye) distortion is not supported by '
                              'rig calibration; use plumb_bob or rational_polynomial')
    return name, Intrinsics(np.array(model.K), np.array(model.D), model.size,
                            source=f'file {path}')


def per_view_errors(intrinsics: Intrinsics, views: Dict[str, np.ndarray],
                    object_points: np.ndarray) -> Dict[str, float]:
    """Per-view reprojection RMS (px) under given intrinsics (solvePnP per view)."""
    return {i: view_rms(object_points, c, intrinsics.K, intrinsics.D)[0]
            for i, c in sorted(views.items())}


def coverage_fraction(corner_sets: List[np.ndarray], size: Tuple[int, int],
                      cells: Tuple[int, int] = (8, 6)) -> float:
    """Fraction of an ``8 x 6`` grid of image cells that hold at least one detected corner."""
    w, h = size
    hit = np.zeros(cells[::-1], dtype=bool)
    for corners in corner_sets:
        c = np.asarray(corners).reshape(-1, 2)
        col = np.clip((c[:, 0] / w * cells[0]).astype(int), 0, cells[0] - 1)
        row = np.clip((c[:, 1] / h * cells[1]).astype(int), 0, cells[1] - 1)
        hit[row, col] = True
    return float(hit.mean())
