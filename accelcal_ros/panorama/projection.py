r"""
Panorama pixel <-> ray: the panorama's frames contract.

Panorama frame ``P`` (an optical-style, levelled frame): ``z`` is the horizontal heading
of the reference camera, ``x`` points right (horizontal), ``y`` points down (along
gravity). A ray at azimuth ``az`` (positive to the right) and elevation ``el`` (positive
up) is

.. math::  M_P = [\cos el \sin az,\ -\sin el,\ \cos el \cos az]^T

which is paper A's sphere point (step 2 of its algorithm) with ``y`` negated so that the
frame is the right-handed optical one (x right, y down, z forward).

Pixel coordinates are continuous with **integer values at pixel centres** (the OpenCV
convention, so ``cv2.remap`` needs no half-pixel shift). The angles of pixel ``(u, v)``
refer to its centre:

.. math::

    az(u) = \Delta\alpha \left(\frac{u + 1/2}{W} - \frac12\right), \qquad
    el(v) = \Delta\beta \left(\frac12 - \frac{v + 1/2}{H}\right)  \ \text{(spherical)}

so column 0's left edge is at ``-fov_h/2`` and the last column's right edge at
``+fov_h/2``; the top edge of row 0 is at ``+fov_v/2``. Paper A's
``psi = 0.5 d_alpha (2u/W - 1)`` is the same mapping evaluated at the pixel's left edge
(``u - 1/2`` here). The true horizon (``el = 0``) lies at row coordinate ``(H - 1)/2``:
the middle row for odd ``H``, the boundary between the two middle rows for even ``H``.

Cylindrical projection (unit cylinder about the vertical axis): columns are equal-angle
as above; rows are equal steps of height ``h = tan(el)``, from ``tan(fov_v/2)`` at the top
edge to ``-tan(fov_v/2)`` at the bottom edge, again evaluated at pixel centres.

Both projections are separable: azimuth depends on the column only, elevation on the row
only, which :mod:`.lookup` exploits.
"""
from dataclasses import dataclass
from typing import Tuple

from accelcal_ros.errors import InputError
import numpy as np
from numpy.typing import ArrayLike

PROJECTIONS = ('spherical', 'cylindrical')
MAX_CYLINDRICAL_FOV_V_DEG = 170.0


@dataclass(frozen=True)
class PanoramaGeometry:
    """
    Size, angular extent and projection of the panorama sector.

    ``fov_h_deg`` in (0, 360], ``fov_v_deg`` in (0, 180] (spherical) or (0, 170]
    (cylindrical); ``width``, ``height`` in pixels.
    """

    width: int = 3600
    height: int = 2400
    fov_h_deg: float = 180.0
    fov_v_deg: float = 120.0
    projection: str = 'spherical'

    def __post_init__(self):
        """Validate the values; raise :class:`InputError` with the reason."""
        for name in ('width', 'height'):
            value = getattr(self, name)
            if isinstance(value, bool) or int(value) != value or not 2 <= value <= 30000:
                raise InputError(f'panorama {name} must be an integer in [2, 30000], '
                                 f'got {value!r}')
            object.__setattr__(self, name, int(value))
        if self.projection not in PROJECTIONS:
            raise InputError(f'projection must be one of {", ".join(PROJECTIONS)}, '
                             f'got {self.projection!r}')
        fov_h, fov_v = float(self.fov_h_deg), float(self.fov_v_deg)
        if not (np.isfinite(fov_h) and 0.0 < fov_h <= 360.0):
            raise InputError(f'fov_h_deg must be in (0, 360], got {self.fov_h_deg!r}')
        top = MAX_CYLINDRICAL_FOV_V_DEG if self.projection == 'cylindrical' else 180.0
        if not (np.isfinite(fov_v) and 0.0 < fov_v <= top):
            raise InputError(f'fov_v_deg must be in (0, {top:g}] for a {self.projection} '
                             f'panorama, got {self.fov_v_deg!r}')
        object.__setattr__(self, 'fov_h_deg', fov_h)
        object.__setattr__(self, 'fov_v_deg', fov_v)

    @property
    def shape(self) -> Tuple[int, int]:
        """Return ``(height, width)``."""
        return self.height, self.width

    def azimuth_rad(self, u: ArrayLike) -> np.ndarray:
        """Azimuth (rad, positive right) of continuous column ``u`` (integers = centres)."""
        u = np.asarray(u, dtype=float)
        return np.radians(self.fov_h_deg) * ((u + 0.5) / self.width - 0.5)

    def elevation_rad(self, v: ArrayLike) -> np.ndarray:
        """Elevation (rad, positive up) of continuous row ``v`` (integers = centres)."""
        v = np.asarray(v, dtype=float)
        t = 0.5 - (v + 0.5) / self.height
        if self.projection == 'spherical':
            return np.radians(self.fov_v_deg) * t
        return np.arctan(2.0 * t * np.tan(np.radians(self.fov_v_deg) / 2.0))

    def column_from_azimuth(self, azimuth_rad: ArrayLike) -> np.ndarray:
        """Continuous column of an azimuth (inverse of :meth:`azimuth_rad`)."""
        a = np.asarray(azimuth_rad, dtype=float)
        return (a / np.radians(self.fov_h_deg) + 0.5) * self.width - 0.5

    def row_from_elevation(self, elevation_rad: ArrayLike) -> np.ndarray:
        """Continuous row of an elevation (inverse of :meth:`elevation_rad`)."""
        e = np.asarray(elevation_rad, dtype=float)
        if self.projection == 'spherical':
            t = e / np.radians(self.fov_v_deg)
        else:
            t = np.tan(e) / (2.0 * np.tan(np.radians(self.fov_v_deg) / 2.0))
        return (0.5 - t) * self.height - 0.5

    def horizon_row(self) -> float:
        """Row coordinate of the true horizon, ``(H - 1) / 2``."""
        return (self.height - 1) / 2.0

    def pixels_per_radian_vertical(self, elevation_rad: ArrayLike = 0.0) -> np.ndarray:
        """Rows per radian of elevation at ``elevation_rad`` (for pixel error budgets)."""
        if self.projection == 'spherical':
            return self.height / np.radians(self.fov_v_deg)
        scale = self.height / (2.0 * np.tan(np.radians(self.fov_v_deg) / 2.0))
        return scale / np.cos(elevation_rad) ** 2

    def rays(self, u: ArrayLike, v: ArrayLike) -> np.ndarray:
        """
        Return unit rays ``(..., 3)`` in the panorama frame ``P`` for pixel coordinates.

        ``u`` and ``v`` broadcast together; integer values are pixel centres.
        """
        return rays_from_angles(self.azimuth_rad(u), self.elevation_rad(v))

    def pixels(self, rays: ArrayLike) -> Tuple[np.ndarray, np.ndarray]:
        """Continuous ``(u, v)`` of rays ``(..., 3)`` in frame ``P`` (any length)."""
        r = np.asarray(rays, dtype=float)
        azimuth = np.arctan2(r[..., 0], r[..., 2])
        elevation = np.arctan2(-r[..., 1], np.hypot(r[..., 0], r[..., 2]))
        return self.column_from_azimuth(azimuth), self.row_from_elevation(elevation)


def rays_from_angles(azimuth_rad: ArrayLike, elevation_rad: ArrayLike) -> np.ndarray:
    """Return unit rays in frame ``P`` from azimuth (right +), elevation (up +), radians."""
    a, e = np.broadcast_arrays(np.asarray(azimuth_rad, dtype=float),
                               np.asarray(elevation_rad, dtype=float))
    ce = np.cos(e)
    return np.stack([ce * np.sin(a), -np.sin(e), ce * np.cos(a)], axis=-1)
