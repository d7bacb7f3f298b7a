"""
A levelled view's pose and pinhole geometry: direction, zoom, size caps, ``K``, the horizon.

Conventions (as the panorama's): azimuth 0 is the panorama's centre column (the body's
heading), positive to the right; elevation positive up (rad). The view is a pinhole with
``fx = fy = (W/2) / tan(fov_h/2)``, ``cx = (W-1)/2``, ``cy = (H-1)/2``; its optical frame
(REP-103 ``_optical_frame``: z forward, x right, y down) is turned from the panorama frame
``P`` by :func:`view_rotation`. Used by :mod:`.view` (the renderer) and everything that
steers one (the node, ``accelcal serve``, the study).
"""
from dataclasses import dataclass
import math
from typing import Any, Optional, Tuple

from accelcal_ros.errors import InputError
import numpy as np

MAX_VIEW_SIDE_PX = 4096
"""Largest width or height of a view (a 4096 x 4096 view's lookup is 128 MB)."""
MIN_VIEW_SIDE_PX = 16
"""Smallest width or height of a view."""
MAX_FOV_H_DEG = 170.0
"""Widest horizontal field of view accepted (a pinhole reaches infinity at 180 deg)."""
MIN_FOV_H_DEG = 0.5
"""Narrowest horizontal field of view accepted (an electronic zoom of ~100x)."""
MAX_AZIMUTH_TURNS = 10000
"""Largest azimuth accepted, in turns either way (a head tracker's unwrapped yaw is
wrapped into [-180, 180) deg); beyond it the number names no direction (``1e308`` deg)."""


def finite_number(name: str, value: Any) -> float:
    """
    Return ``value`` as a finite float, or raise :class:`InputError` naming ``name``.

    Booleans and strings are not numbers here (``float(True)`` is 1: a JSON ``true``
    would turn a view by a degree; a JSON ``"45"`` or ``"1_0"`` was read as 45 and 10);
    an integer too large for a float is not finite.
    """
    if isinstance(value, (bool, np.bool_, str, bytes)):
        raise InputError(f'view {name} must be a number, got {value!r:.40}')
    try:
        number = float(value)
    except OverflowError:
        raise InputError(f'view {name} must be finite, got a number too large for a '
                         'float; keeping the last view') from None
    except (TypeError, ValueError):
        raise InputError(f'view {name} must be a number, got {value!r}') from None
    if not math.isfinite(number):
        raise InputError(f'view {name} must be finite, got {value!r}; keeping the last view')
    return number


@dataclass(frozen=True)
class ViewPose:
    """
    Where a view looks and its zoom: azimuth, elevation, horizontal field of view (rad).

    ``azimuth_rad`` (0 = the panorama's centre column, positive right; wrapped into
    [-pi, pi)), ``elevation_rad`` in [-pi/2, pi/2] (positive up), ``fov_h_rad`` in
    [0.5, 170] deg. Out-of-range or non-finite values raise :class:`InputError`.
    """

    azimuth_rad: float = 0.0
    elevation_rad: float = 0.0
    fov_h_rad: float = math.radians(60.0)

    def __post_init__(self) -> None:
        """Check and normalise the values (one clear reason per bad value)."""
        az = finite_number('azimuth', self.azimuth_rad)
        el = finite_number('elevation', self.elevation_rad)
        fov = finite_number('fov_h', self.fov_h_rad)
        if abs(az) > 2.0 * math.pi * MAX_AZIMUTH_TURNS:
            raise InputError(f'view azimuth must be within +-{MAX_AZIMUTH_TURNS} turns '
                             f'(+-{360 * MAX_AZIMUTH_TURNS:.0f} deg), got '
                             f'{math.degrees(az):.6g} deg; keeping the last view')
        if not -math.pi / 2 - 1e-12 <= el <= math.pi / 2 + 1e-12:
            raise InputError(f'view elevation must be within +-90 deg, got '
                             f'{math.degrees(el):.6g} deg')
        if not math.radians(MIN_FOV_H_DEG) - 1e-12 <= fov <= math.radians(MAX_FOV_H_DEG) + 1e-12:
            raise InputError(f'view fov_h must be in [{MIN_FOV_H_DEG:g}, {MAX_FOV_H_DEG:g}] deg '
                             f'for a rectilinear view (0 and 180 are impossible), got '
                             f'{math.degrees(fov):.6g} deg')
        az = (az + math.pi) % (2.0 * math.pi) - math.pi
        object.__setattr__(self, 'azimuth_rad', az)
        object.__setattr__(self, 'elevation_rad', min(max(el, -math.pi / 2), math.pi / 2))
        object.__setattr__(self, 'fov_h_rad', fov)

    @classmethod
    def from_degrees(cls, azimuth_deg: float, elevation_deg: float,
                     fov_h_deg: float) -> 'ViewPose':
        """Return the pose from degrees (checked as the constructor)."""
        return cls(math.radians(finite_number('azimuth', azimuth_deg)),
                   math.radians(finite_number('elevation', elevation_deg)),
                   math.radians(finite_number('fov_h', fov_h_deg)))

    def degrees(self) -> Tuple[float, float, float]:
        """Return ``(azimuth, elevation, fov_h)`` in degrees."""
        return (math.degrees(self.azimuth_rad), math.degrees(self.elevation_rad),
                math.degrees(self.fov_h_rad))


def check_view_size(width: Any, height: Any) -> Tuple[int, int]:
    """Return ``(width, height)`` as ints, or raise :class:`InputError` beyond the caps."""
    out = []
    for name, value in (('width', width), ('height', height)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) and not (
                isinstance(value, float) and value.is_integer()):
            raise InputError(f'view {name} must be an integer, got {value!r}')
        if not MIN_VIEW_SIDE_PX <= int(value) <= MAX_VIEW_SIDE_PX:
            raise InputError(f'view {name} must be in [{MIN_VIEW_SIDE_PX}, '
                             f'{MAX_VIEW_SIDE_PX}] px, got {value}')
        out.append(int(value))
    return out[0], out[1]


def focal_px(width: int, fov_h_rad: float) -> float:
    """Return the view's focal length ``(W/2) / tan(fov_h/2)`` in pixels."""
    return (width / 2.0) / math.tan(fov_h_rad / 2.0)


def view_camera_matrix(width: int, height: int, fov_h_rad: float) -> np.ndarray:
    """Return the view's ``K`` (3x3): ``fx = fy = (W/2)/tan(fov_h/2)``, ``(W-1)/2, (H-1)/2``."""
    f = focal_px(width, fov_h_rad)
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0],
                     [0.0, 0.0, 1.0]])


def view_rotation(azimuth_rad: float, elevation_rad: float) -> np.ndarray:
    """Return ``R_PV``: view optical frame -> panorama frame ``P`` (columns x_V, y_V, z_V)."""
    ca, sa = math.cos(azimuth_rad), math.sin(azimuth_rad)
    ce, se = math.cos(elevation_rad), math.sin(elevation_rad)
    # columns x_V = [ca, 0, -sa], y_V = z_V x x_V, z_V = [ce sa, -se, ce ca]
    return np.array([[ca, se * sa, ce * sa], [0.0, ce, -se], [-sa, se * ca, ce * ca]])


def horizon_row_px(height: int, width: int, pose: ViewPose) -> float:
    """Return ``c_y + f tan(elevation)``: the horizon's row, also beyond the view (px)."""
    return (height - 1) / 2.0 + focal_px(width, pose.fov_h_rad) * math.tan(pose.elevation_rad)


def horizon_row(height: int, width: int, pose: ViewPose) -> Optional[float]:
    """
    Return the row of the true horizon in a levelled view, or None when it is not in view.

    The row is ``c_y + f tan(elevation)``, the same in every column. It is given only
    within the image, from the top edge of its first row to the bottom edge of its last
    (``-0.5 <= row <= H - 0.5``); a horizon above or below the view is None, and so is
    the one at elevation +-90 deg, which lies at infinity (``tan`` of the rounded angle
    would give some 1e16 instead).
    """
    row = horizon_row_px(height, width, pose)
    return row if -0.5 <= row <= height - 0.5 else None
