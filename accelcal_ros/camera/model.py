"""
One camera model: intrinsics, lens distortion, vectorised projection and its inverse.

Frames and conventions:

- Points and rays are in the camera's optical frame (REP-103 ``_optical``): z forward
  along the optical axis, x right, y down; units are whatever the caller uses (m).
- Pixels follow OpenCV: ``(u, v)`` = (column, row), integer values at pixel centres,
  ``(0, 0)`` the centre of the top-left pixel.
- ``K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` (pixels; ``s`` the skew, usually 0):
  ``u = fx x_d + s y_d + cx``, ``v = fy y_d + cy`` for distorted normalised
  coordinates ``(x_d, y_d)`` (:mod:`accelcal_ros.camera.distortion`), exactly as
  ``cv2.projectPoints`` (``plumb_bob``, ``rational_polynomial``) and
  ``cv2.fisheye.projectPoints`` (``equidistant``, with ``alpha = s / fx``).

The mapping form (:meth:`CameraModel.to_mapping`, :func:`camera_model_from_mapping`) is
what the rig file and a ``CameraInfo`` carry: ``width``, ``height``, ``K`` (9 values,
row-major), ``D`` and ``distortion_model``. :func:`camera_model_from_mapping` also reads
the ROS calibration YAML of ``camera_calibration_parsers`` (``image_width``,
``camera_matrix: {data: [...]}``, ``distortion_coefficients``...).
"""
from dataclasses import dataclass, field
import math
from typing import Any, Dict, Mapping, Optional, Sequence, Tuple

from accelcal_ros.camera.distortion import (COEFFICIENT_COUNTS, distort_normalized,
                                            DISTORTION_MODELS, EQUIDISTANT, PLUMB_BOB,
                                            RATIONAL_POLYNOMIAL, undistort_equidistant_angle,
                                            undistort_normalized)
from accelcal_ros.errors import InputError
from accelcal_ros.textformats import yaml_number
import numpy as np

MAX_SIDE_PX = 100000
MAX_FOCAL_PX = 1e6
"""Largest focal length (px) taken: 1e6 px is a 0.06 deg field of view on a 1000 px image."""
MIN_FOCAL_PX = 1.0
"""Smallest focal length (px) taken: below a pixel no lens images anything."""
MAX_DISTORTION_COEFFICIENT = 1000.0
"""Largest ``|D_i|`` taken: real lenses (rational models included) stay far below; a
larger value is a broken file that would fold the image."""
"""Largest image width or height accepted (pixels)."""


def _coefficients(values: Any, model: str, where: str) -> Tuple[np.ndarray, str]:
    """Return the coefficients padded to the model's count, and the model name."""
    d = np.asarray(values, dtype=float).reshape(-1)
    if not np.all(np.isfinite(d)):
        raise InputError(f'{where}D contains NaN or infinity')
    if d.size and np.abs(d).max() > MAX_DISTORTION_COEFFICIENT:
        raise InputError(f'{where}D = {d.tolist()} has a coefficient beyond '
                         f'+-{MAX_DISTORTION_COEFFICIENT:g}: no lens distorts like that '
                         '(broken file or wrong units)')
    model = model or PLUMB_BOB
    if model not in DISTORTION_MODELS:
        if not np.any(d):
            model = PLUMB_BOB  # no distortion: the model name does not matter
        else:
            raise InputError(f'{where}distortion_model {model!r} is not supported; use '
                             f'one of {", ".join(DISTORTION_MODELS)}')
    if model == EQUIDISTANT:
        if d.size not in (0, 4):
            raise InputError(f'{where}D needs 4 coefficients [k1, k2, k3, k4] for '
                             f'equidistant distortion, got {d.size}')
        return (d if d.size else np.zeros(4)), model
    if d.size not in (0, 4, 5, 8):
        raise InputError(f'{where}D needs 4, 5 or 8 coefficients [k1, k2, p1, p2'
                         f'[, k3[, k4, k5, k6]]], got {d.size}')
    if d.size == 8 and model == PLUMB_BOB:
        # OpenCV reads D by its length: 8 values are the rational model
        if np.any(d[5:]):
            model = RATIONAL_POLYNOMIAL
        else:
            d = d[:5]
    count = COEFFICIENT_COUNTS[model]
    out = np.zeros(count)
    out[:d.size] = d
    return out, model


def _camera_matrix(k: Any, where: str) -> np.ndarray:
    """Return ``K`` 3x3 from 9 values (scaled so that ``K[2, 2] = 1``), validated."""
    try:
        k = np.asarray(k, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(f'{where}K must be 9 numbers, got {k!r}') from None
    if k.size != 9:
        raise InputError(f'{where}K needs 9 values (row-major 3x3), got {k.size}')
    if not np.all(np.isfinite(k)):
        raise InputError(f'{where}K contains NaN or infinity')
    k = k.reshape(3, 3)
    if k[2, 2] > 0:
        with np.errstate(over='ignore'):
            k = k / k[2, 2]
    if (not k[0, 0] > 0 or not k[1, 1] > 0 or k[1, 0] != 0.0
            or np.abs(k[2] - [0.0, 0.0, 1.0]).max() > 1e-9):
        zero = ' (an all-zero K: the camera is not calibrated)' if not k.any() else ''
        raise InputError(f'{where}K must be [fx, s, cx, 0, fy, cy, 0, 0, 1] with focal '
                         f'lengths fx, fy > 0, got {k.reshape(-1).tolist()}{zero}')
    limit = MAX_FOCAL_PX
    if not (np.all(np.isfinite(k)) and MIN_FOCAL_PX <= k[0, 0] <= limit
            and MIN_FOCAL_PX <= k[1, 1] <= limit
            and abs(k[0, 1]) <= k[0, 0] and abs(k[0, 2]) <= 2 * MAX_SIDE_PX
            and abs(k[1, 2]) <= 2 * MAX_SIDE_PX):
        raise InputError(f'{where}K = {k.reshape(-1).tolist()} is not a camera: focal lengths '
                         f'must be {MIN_FOCAL_PX:g}..{limit:g} px, the skew at most fx and the '
                         f'principal point within +-{2 * MAX_SIDE_PX} px (broken file or wrong '
                         'units)')
    return k


def check_principal_point(k: np.ndarray, width: int, height: int, where: str) -> None:
    """
    Refuse a principal point outside a known image (``width``, ``height`` > 0; pixels).

    A calibrated lens centres within its image; ``cx = 5000`` for a 640 px image was
    accepted (P2P ranges of 62.9 and 362.7 m for a true 6.1 m, status 0).
    """
    cx, cy = float(k[0, 2]), float(k[1, 2])
    if width > 0 and height > 0 and not (0.0 <= cx <= width and 0.0 <= cy <= height):
        raise InputError(f'{where}K: the principal point ({cx:g}, {cy:g}) px lies outside the '
                         f'{width}x{height} image (a calibrated lens centres within it: '
                         "another camera's K, or a broken file?)")


def _side(value: Any, key: str, where: str, allow_zero: bool) -> int:
    low = 0 if allow_zero else 1
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) \
            or not low <= value <= MAX_SIDE_PX:
        raise InputError(f'{where}{key} must be an integer in {low}..{MAX_SIDE_PX} (pixels), '
                         f'got {value!r}')
    return int(value)


@dataclass(frozen=True, eq=False)
class CameraModel:
    """
    A calibrated camera: image size, ``K`` 3x3 (pixels), distortion ``D`` and its model.

    ``width``/``height`` in pixels (0: unknown, as a ``CameraInfo`` may say). ``D`` holds
    5 (``plumb_bob``), 8 (``rational_polynomial``) or 4 (``equidistant``) coefficients;
    shorter OpenCV lists (0 or 4 values) are padded with zeros. Raises
    :class:`InputError` (its message says which value is wrong) on invalid values.
    """

    width: int
    height: int
    K: np.ndarray
    D: np.ndarray = field(default_factory=lambda: np.zeros(0))
    distortion_model: str = PLUMB_BOB

    def __post_init__(self) -> None:
        """Validate and normalise ``K`` and ``D``; the arrays become read-only."""
        _side(self.width, 'width', '', True)
        _side(self.height, 'height', '', True)
        k = _camera_matrix(self.K, '')
        check_principal_point(k, int(self.width), int(self.height), '')
        d, model = _coefficients(self.D, self.distortion_model, '')
        k.setflags(write=False)
        d.setflags(write=False)
        object.__setattr__(self, 'width', int(self.width))
        object.__setattr__(self, 'height', int(self.height))
        object.__setattr__(self, 'K', k)
        object.__setattr__(self, 'D', d)
        object.__setattr__(self, 'distortion_model', model)

    # -- construction ---------------------------------------------------------------
    @classmethod
    def from_fov(cls, width: int = 1280, height: int = 960, fov_h_deg: float = 60.0,
                 dist_coeffs: Optional[Sequence[float]] = None,
                 distortion_model: str = PLUMB_BOB) -> 'CameraModel':
        """Return a camera with square pixels, centred principal point and ``fov_h_deg``."""
        if not 0.0 < fov_h_deg < 180.0:
            raise InputError(f'fov_h_deg must be in (0, 180), got {fov_h_deg!r}')
        f = 0.5 * width / math.tan(math.radians(fov_h_deg) / 2.0)
        k = np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0],
                      [0.0, 0.0, 1.0]])
        return cls(int(width), int(height), k,
                   np.zeros(0) if dist_coeffs is None else np.asarray(dist_coeffs, dtype=float),
                   distortion_model)

    @classmethod
    def from_camera_info(cls, k: Sequence[float], d: Sequence[float], distortion_model: str,
                         width: int, height: int) -> 'CameraModel':
        """
        Return the model of a ``sensor_msgs/CameraInfo``'s fields (``K`` 9 values).

        Errors say ``camera_info ...`` and what is wrong (an all-zero ``K``: the camera
        is not calibrated).
        """
        where = 'camera_info '
        kk = _camera_matrix(k, where)
        dd, model = _coefficients(d, distortion_model, where)
        width, height = _side(width, 'width', where, True), _side(height, 'height', where, True)
        check_principal_point(kk, width, height, where)
        return cls(width, height, kk, dd, model)

    # -- properties -----------------------------------------------------------------
    @property
    def size(self) -> Tuple[int, int]:
        """Return ``(width, height)`` in pixels."""
        return self.width, self.height

    @property
    def camera_matrix(self) -> np.ndarray:
        """``K`` under OpenCV's name."""
        return self.K

    @property
    def dist_coeffs(self) -> np.ndarray:
        """``D`` under OpenCV's name (pass with :attr:`is_fisheye` to pick the API)."""
        return self.D

    @property
    def is_fisheye(self) -> bool:
        """Return True for the ``equidistant`` model (``cv2.fisheye``)."""
        return self.distortion_model == EQUIDISTANT

    def has_distortion(self) -> bool:
        """Return True if any distortion coefficient is non-zero."""
        return bool(np.any(self.D != 0.0))

    # -- normalised coordinates -----------------------------------------------------
    def distort(self, x: np.ndarray, y: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Apply the lens to undistorted normalised coordinates ``(x, y)`` (any shape)."""
        if not self.has_distortion():
            return x, y
        return distort_normalized(x, y, self.D, self.distortion_model)

    def undistort(self, xd: np.ndarray, yd: np.ndarray,
                  iterations: int = 10) -> Tuple[np.ndarray, np.ndarray]:
        """Invert :meth:`distort` (Newton, float64); see :func:`undistort_normalized`."""
        xd = np.asarray(xd, dtype=float)
        yd = np.asarray(yd, dtype=float)
        if not self.has_distortion():
            return xd, yd
        return undistort_normalized(xd, yd, self.D, self.distortion_model, iterations)

    def pixels_from_distorted(self, xd: np.ndarray,
                              yd: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Apply ``K`` to distorted normalised coordinates; return ``(u, v)`` pixels."""
        k = self.K
        return k[0, 0] * xd + k[0, 1] * yd + k[0, 2], k[1, 1] * yd + k[1, 2]

    def distorted_from_pixels(self, u: np.ndarray,
                              v: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Remove ``K`` from pixels; return distorted normalised ``(x_d, y_d)``."""
        k = self.K
        yd = (np.asarray(v, dtype=float) - k[1, 2]) / k[1, 1]
        xd = (np.asarray(u, dtype=float) - k[0, 2] - k[0, 1] * yd) / k[0, 0]
        return xd, yd

    def normalized_from_pixels(self, u: np.ndarray, v: np.ndarray,
                               iterations: int = 10) -> Tuple[np.ndarray, np.ndarray]:
        """Return undistorted normalised ``(x, y) = (X/Z, Y/Z)`` of pixels (any shape)."""
        return self.undistort(*self.distorted_from_pixels(u, v), iterations=iterations)

    def pixels_from_normalized(self, x: np.ndarray,
                               y: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Return the pixels ``(u, v)`` of undistorted normalised coordinates (any shape)."""
        return self.pixels_from_distorted(*self.distort(x, y))

    # -- 3-D ------------------------------------------------------------------------
    def project(self, points: np.ndarray) -> np.ndarray:
        """
        Return the pixels ``(N, 2)`` of points ``(N, 3)`` (or one ``(3,)``) in the optical frame.

        Points with ``z <= 0`` (at or behind the camera's centre) give NaN. Matches
        ``cv2.projectPoints`` / ``cv2.fisheye.projectPoints`` with zero pose.
        """
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        z = pts[:, 2]
        front = z > 0.0
        safe = np.where(front, z, 1.0)
        u, v = self.pixels_from_normalized(pts[:, 0] / safe, pts[:, 1] / safe)
        uv = np.stack([u, v], axis=1)
        uv[~front] = np.nan
        return uv

    def unproject(self, pixels: np.ndarray, iterations: int = 10) -> np.ndarray:
        """
        Return unit rays ``(N, 3)`` (optical frame) of pixels ``(N, 2)`` (or one ``(2,)``).

        For ``equidistant`` the ray comes from the off-axis angle, so pixels more than
        90 degrees off the axis give rays with ``z <= 0``.
        """
        uv = np.asarray(pixels, dtype=float).reshape(-1, 2)
        xd, yd = self.distorted_from_pixels(uv[:, 0], uv[:, 1])
        if self.is_fisheye and self.has_distortion():
            theta, cos_az, sin_az = undistort_equidistant_angle(xd, yd, self.D, iterations)
            sin_t = np.sin(theta)
            return np.stack([sin_t * cos_az, sin_t * sin_az, np.cos(theta)], axis=1)
        x, y = self.undistort(xd, yd, iterations)
        rays = np.stack([x, y, np.ones_like(x)], axis=1)
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)

    # -- mapping form ---------------------------------------------------------------
    def to_mapping(self) -> Dict[str, Any]:
        """Return ``{width, height, K, D, distortion_model}`` (YAML-ready plain types)."""
        return {'width': self.width, 'height': self.height,
                'K': [float(x) + 0.0 for x in self.K.reshape(-1)],
                'D': [float(x) + 0.0 for x in self.D],
                'distortion_model': self.distortion_model}


CAMERA_KEYS = ('width', 'height', 'K', 'D', 'distortion_model')
"""Keys of the mapping form (``D`` and ``distortion_model`` optional)."""
ROS_CALIBRATION_KEYS = ('image_width', 'image_height', 'camera_name', 'camera_matrix',
                        'distortion_model', 'distortion_coefficients',
                        'rectification_matrix', 'projection_matrix')
"""Keys of a ROS ``camera_calibration_parsers`` YAML file."""


def _numbers(value: Any, where: str, key: str) -> np.ndarray:
    if isinstance(value, Mapping) and 'data' in value:
        value = value['data']
    if not isinstance(value, (list, tuple)) or isinstance(value, str):
        raise InputError(f'{where}{key} must be a list of numbers, got '
                         f'{type(value).__name__}')
    numbers = [yaml_number(v) for v in value]
    if any(v is None for v in numbers):
        raise InputError(f'{where}{key} must contain numbers only, got {value!r}')
    arr = np.array(numbers, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise InputError(f'{where}{key} contains NaN or infinity')
    return arr


def camera_model_from_mapping(entry: Mapping, where: str = 'camera') -> CameraModel:
    """
    Build a :class:`CameraModel` from its mapping form; errors start with ``where: key``.

    Reads ``width``, ``height``, ``K`` (9 values), optional ``D`` (0, 4, 5 or 8 values;
    4 for ``equidistant``) and ``distortion_model`` (default ``plumb_bob``), or the ROS
    calibration YAML keys (``image_width``, ``camera_matrix``...). Other keys are left
    to the caller. Raises :class:`InputError`.
    """
    if not isinstance(entry, Mapping):
        raise InputError(f'{where}: expected a mapping, got {type(entry).__name__}')
    prefix = f'{where}: '
    ros = 'camera_matrix' in entry or 'image_width' in entry
    keys = (('image_width', 'image_height', 'camera_matrix', 'distortion_coefficients')
            if ros else ('width', 'height', 'K', 'D'))
    missing = [key for key in keys[:3] if key not in entry]
    if missing:
        raise InputError(f'{prefix}missing key(s) {", ".join(missing)}')
    width = _side(entry[keys[0]], keys[0], prefix, False)
    height = _side(entry[keys[1]], keys[1], prefix, False)
    k = _camera_matrix(_numbers(entry[keys[2]], prefix, keys[2]), prefix)
    check_principal_point(k, width, height, prefix)
    d_entry = entry.get(keys[3])
    d = np.zeros(0) if d_entry is None else _numbers(d_entry, prefix, keys[3])
    model = entry.get('distortion_model', PLUMB_BOB)
    if not isinstance(model, str):
        raise InputError(f'{prefix}distortion_model must be one of '
                         f'{", ".join(DISTORTION_MODELS)}, got {model!r}')
    d, model = _coefficients(d, model, prefix)
    return CameraModel(width, height, k, d, model)


__all__ = ['CAMERA_KEYS', 'CameraModel', 'camera_model_from_mapping', 'ROS_CALIBRATION_KEYS']
