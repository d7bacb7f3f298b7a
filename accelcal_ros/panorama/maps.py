"""
Exact lookup maps and blend maps: every panorama pixel evaluated (numpy).

A map is a float32 array ``(height, width, 2)`` of mosaic coordinates ``(x, y)``
(:mod:`.mosaic`); pixels no camera sees hold :data:`~.mosaic.OUTSIDE`.
:class:`MapBuilder` evaluates every pixel through :class:`~.rig_projection.RigProjection`
(about a second at 3600x2400): the reference of the fast builder
(:class:`~.lookup.LookupBuilder`), and the maps of feathered blending.
"""

from typing import Dict, Optional, Tuple, TYPE_CHECKING, Union

from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA
from accelcal_ros.panorama.mosaic import MosaicLayout, OUTSIDE
from accelcal_ros.panorama.rig_projection import RigProjection
import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:  # pragma: no cover - annotations only
    from accelcal_ros.camera.rig import Rig
    from accelcal_ros.panorama.projection import PanoramaGeometry


class MapBuilder(RigProjection):
    """
    Exact and blend maps of a rig into a panorama geometry at a tilt.

    ``gap`` (px) separates the images in the mosaic (:class:`~.mosaic.MosaicLayout`).
    :attr:`band` is ``(first, last + 1)``: the rows some camera saw in the last map.
    """

    def __init__(self, rig: 'Rig', geometry: 'PanoramaGeometry',
                 imu_to_camera: ArrayLike = DEFAULT_IMU_TO_CAMERA, gap: int = 32) -> None:
        super().__init__(rig, geometry, imu_to_camera)
        self._place_images(gap)
        self._set_ray_tables(0, geometry.width, geometry.height)
        self.band: Tuple[int, int] = (0, geometry.height)
        self.last_stats: Dict[str, float] = {}

    def _place_images(self, gap: int) -> None:
        """Lay the rig's images out in the mosaic, ``gap`` pixels apart."""
        self.layout = MosaicLayout.for_rig(self.rig, gap=gap)
        self._offsets = np.asarray(self.layout.offsets, dtype=np.float32)

    def _set_ray_tables(self, pad: int, cols_end: int, rows_end: int) -> None:
        """Separable ray tables of pixels ``-pad .. end - 1`` per axis (index = pixel + pad)."""
        self._pad = pad
        az = self.geometry.azimuth_rad(np.arange(-pad, cols_end))
        el = self.geometry.elevation_rad(np.arange(-pad, rows_end))
        self._sin_az = np.sin(az).astype(np.float32)
        self._cos_az = np.cos(az).astype(np.float32)
        self._sin_el = np.sin(el).astype(np.float32)
        self._cos_el = np.cos(el).astype(np.float32)

    def to_mosaic(self, label: np.ndarray, x: np.ndarray, y: np.ndarray,
                  side: np.ndarray) -> np.ndarray:
        """Mosaic coordinates ``(N, 2)`` float32 of :meth:`evaluate`'s output."""
        out = np.empty((len(label), 2), np.float32)
        out[:, 0] = x + self._offsets[label, 0]
        out[:, 1] = y + self._offsets[label, 1]
        out[side != 0] = OUTSIDE
        return out

    def _pixel_rays(self, u, v):
        """Rays ``(3, ...)`` float32 of integer pixel coordinates from the separable tables."""
        u, v = u + self._pad, v + self._pad
        ce = self._cos_el[v]
        rays = np.empty((3,) + np.broadcast(u, v).shape, np.float32)
        np.multiply(ce, self._sin_az[u], out=rays[0])
        rays[1] = -self._sin_el[v]
        np.multiply(ce, self._cos_az[u], out=rays[2])
        return rays

    def build_exact(self, roll: float, pitch: float, with_labels: bool = False,
                    rows_per_chunk: int = 8) -> Union[np.ndarray, Tuple[np.ndarray, np.ndarray]]:
        """
        Evaluate every pixel: map ``(H, W, 2)`` float32 (and labels, -1 where unseen).

        The reference against which the fast builder is tested.
        """
        q = self.camera_rotations(roll, pitch)
        h, w = self.geometry.height, self.geometry.width
        out = np.empty((h, w, 2), np.float32)
        labels: Optional[np.ndarray] = np.empty((h, w), np.int8) if with_labels else None
        cols = np.arange(w)
        for r0 in range(0, h, rows_per_chunk):
            rows = np.arange(r0, min(h, r0 + rows_per_chunk))
            rays = self._pixel_rays(cols[None, :], rows[:, None]).reshape(3, -1)
            label, x, y, side = self._evaluate_soa(rays, q)
            out[rows[0]:rows[-1] + 1] = self.to_mosaic(label, x, y, side).reshape(
                len(rows), w, 2)
            if labels is not None:
                labels[rows[0]:rows[-1] + 1] = np.where(side == 0, label, -1).reshape(
                    len(rows), w)
        covered = np.nonzero((out[..., 0] != OUTSIDE).any(axis=1))[0]
        self.band = (int(covered[0]), int(covered[-1]) + 1) if covered.size else (0, 0)
        return (out, labels) if labels is not None else out

    def build_blend(self, roll: float, pitch: float, width_rad: float,
                    rows_per_chunk: int = 8) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """
        Exact maps for feathered blending: ``(map1, map2, weight1)``.

        Among the cameras whose frame holds a ray, ``map1`` samples the one with the
        closest optical axis (eq. 6 restricted to cameras that see the ray) and ``map2``
        the next one (:data:`OUTSIDE` if none). ``weight1`` (float32) is 1 farther than
        ``width_rad / 2`` from the seam plane between the two axes and falls linearly to
        0.5 on it, so the panorama is continuous across the seam.
        """
        q = self.camera_rotations(roll, pitch)
        h, w = self.geometry.height, self.geometry.width
        n = len(self.rig)
        map1 = np.full((h, w, 2), OUTSIDE, np.float32)
        map2 = np.full((h, w, 2), OUTSIDE, np.float32)
        weight = np.ones((h, w), np.float32)
        axes = q[:, 2, :]
        cols = np.arange(w)
        for r0 in range(0, h, rows_per_chunk):
            rows = np.arange(r0, min(h, r0 + rows_per_chunk))
            rays = self._pixel_rays(cols[None, :], rows[:, None]).reshape(3, -1)
            count = rays.shape[1]
            score = np.full((count, n), -np.inf, np.float32)
            coords = np.empty((n, count, 2), np.float32)
            for i in range(n):
                _, x, y, side = self._evaluate_soa(rays, q, only=i)
                seen = side == 0
                a = axes[i].astype(np.float32)
                score[seen, i] = (a[0] * rays[0] + a[1] * rays[1] + a[2] * rays[2])[seen]
                coords[i] = self.to_mosaic(np.full(count, i), x, y, side)
            order = np.argsort(-score, axis=1)[:, :2]
            best, second = order[:, 0], order[:, 1] if n > 1 else order[:, 0]
            index = np.arange(count)
            has1 = np.isfinite(score[index, best])
            has2 = (np.isfinite(score[index, second]) & (second != best)) & has1
            m1 = np.where(has1[:, None], coords[best, index], OUTSIDE)
            m2 = np.where(has2[:, None], coords[second, index], OUTSIDE)
            gap = np.linalg.norm(axes[best] - axes[second], axis=1)
            dist = np.arcsin(np.clip((score[index, best] - np.where(has2, score[
                index, second], 0.0)) / np.maximum(gap, 1e-9), 0.0, 1.0))
            w1 = np.where(has2, np.clip(0.5 + dist / width_rad, 0.5, 1.0), 1.0)
            sl = slice(rows[0], rows[-1] + 1)
            map1[sl] = m1.reshape(len(rows), w, 2)
            map2[sl] = m2.reshape(len(rows), w, 2)
            weight[sl] = w1.reshape(len(rows), w)
        covered = np.nonzero((map1[..., 0] != OUTSIDE).any(axis=1))[0]
        self.band = (int(covered[0]), int(covered[-1]) + 1) if covered.size else (0, 0)
        return map1, map2, weight
