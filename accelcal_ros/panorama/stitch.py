"""
The stitcher: camera images + attitude -> levelled panorama, one ``cv2.remap`` per frame.

Camera images are copied into a mosaic (all images side by side, black gaps between
them, see :class:`~.mosaic.MosaicLayout`); a lookup map built by
:meth:`~.lookup.LookupBuilder.build_fast` turns the mosaic into the panorama with one
bilinear ``cv2.remap``, zero outside every frame (paper A, steps 5-6). The map is
rebuilt only when the reference camera's tilt moves by more than
``rebuild_threshold_deg`` (the rotation angle between the old and the new tilt); only the
rows some camera sees are remapped, the others stay black. After two frames on the same
map it is converted to OpenCV's fixed-point form, which remaps 6-20 % faster (OpenCV
4.6 and 5.0).

Optional feathered blending (``blend_width_deg > 0``, off by default as in the paper):
in overlaps, the two closest cameras that see a ray are mixed with weights ramping
linearly across a band of that angular width centred on the eq.-6 seam. Its maps are
built exactly, pixel by pixel (seconds at 3600x2400): use it for a static rig or
offline.
"""
import math
import time
from typing import Any, List, Optional, Sequence, Tuple, TYPE_CHECKING

from accelcal_ros.camera.rig import resolve_imu_to_camera
from accelcal_ros.errors import InputError
from accelcal_ros.panorama.lookup import LookupBuilder
from accelcal_ros.panorama.rig_projection import tilt_matrix
import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:  # pragma: no cover - annotations only
    from concurrent.futures import ThreadPoolExecutor


def rotation_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Return the angle (degrees) of the rotation ``a b^T`` between two rotation matrices."""
    cosine = (np.trace(a @ b.T) - 1.0) / 2.0
    return math.degrees(math.acos(min(1.0, max(-1.0, cosine))))


def _finite_attitude(roll: float, pitch: float) -> Tuple[float, float]:
    """Return ``(roll, pitch)`` as floats, or raise :class:`InputError` unless finite."""
    roll, pitch = float(roll), float(pitch)
    if not (math.isfinite(roll) and math.isfinite(pitch)):
        raise InputError(f'attitude must be finite numbers, got roll={roll}, '
                         f'pitch={pitch}; keeping the previous lookup')
    return roll, pitch


class Stitcher:
    """
    Levelled panorama from the images of a calibrated rig and the reference attitude.

    ``channels`` is 3 (colour, any channel order: the output has the input's order) or
    1 (grey). ``imu_to_camera`` (IMU body -> reference camera optical frame) defaults
    to the rig's (:func:`~.rig.resolve_imu_to_camera`). Typical use::

        stitcher = Stitcher(rig, PanoramaGeometry(3600, 2400, 180, 120))
        stitcher.set_attitude(roll, pitch)       # radians, REP-103 body attitude
        for i, image in enumerate(images):
            stitcher.set_image(i, image)
        panorama = stitcher.render()             # owned by the stitcher: copy to keep
    """

    def __init__(self, rig: Any, geometry: Any, imu_to_camera: Optional[ArrayLike] = None,
                 grid_step: int = 20, tolerance_px: float = 0.1,
                 rebuild_threshold_deg: float = 0.01, blend_width_deg: float = 0.0,
                 channels: int = 3) -> None:
        import cv2

        if channels not in (1, 3):
            raise InputError(f'channels must be 1 or 3, got {channels!r}')
        if not (math.isfinite(rebuild_threshold_deg) and rebuild_threshold_deg >= 0):
            raise InputError('rebuild_threshold_deg must be >= 0, got '
                             f'{rebuild_threshold_deg!r}')
        if not (math.isfinite(blend_width_deg) and 0 <= blend_width_deg <= 90):
            raise InputError(f'blend_width_deg must be in [0, 90], got {blend_width_deg!r}')
        if imu_to_camera is None:  # the rig file's, else the default mounting
            imu_to_camera = resolve_imu_to_camera(rig)[0]
        self._cv2 = cv2
        self.rig = rig
        self.geometry = geometry
        self.channels = channels
        self.rebuild_threshold_deg = float(rebuild_threshold_deg)
        self.blend_width_deg = float(blend_width_deg)
        self.builder = LookupBuilder(rig, geometry, imu_to_camera, grid_step, tolerance_px)
        layout = self.builder.layout
        shape = (layout.height, layout.width) + ((channels,) if channels == 3 else ())
        self.mosaic = np.zeros(shape, np.uint8)
        self._out = np.zeros(geometry.shape + ((channels,) if channels == 3 else ()),
                             np.uint8)
        self._map: Optional[np.ndarray] = None  # (H, W, 2) float32 panorama -> mosaic
        self._fixed: Optional[Tuple[np.ndarray, np.ndarray]] = None  # cv2.convertMaps of it
        self._blend: Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]] = None
        self._band = (0, 0)
        self._drawn = (0, 0)
        self._frames_on_map = 0
        self._tilt: Optional[np.ndarray] = None
        self._copy_pool: Optional['ThreadPoolExecutor'] = None
        self.attitude: Optional[Tuple[float, float]] = None
        self.rebuild_count = 0
        self.last_rebuild_s = float('nan')

    # -- attitude -------------------------------------------------------------------------
    def needs_rebuild(self, roll: float, pitch: float) -> bool:
        """Return True when the tilt moved more than the threshold since the last build."""
        if self._tilt is None:
            return True
        moved = rotation_angle_deg(tilt_matrix(roll, pitch, self.builder.imu_to_camera),
                                   self._tilt)
        return moved > self.rebuild_threshold_deg

    def set_attitude(self, roll: float, pitch: float, force: bool = False) -> bool:
        """
        Set the reference camera's roll and pitch (radians, REP-103 body attitude).

        Rebuilds the lookup when needed; returns True if it did. NaN or infinite angles
        raise :class:`InputError` and leave the current map in place.
        """
        roll, pitch = _finite_attitude(roll, pitch)
        if not force and not self.needs_rebuild(roll, pitch):
            return False
        start = time.perf_counter()
        if self.blend_width_deg > 0:
            self._blend = self.builder.build_blend(roll, pitch,
                                                   math.radians(self.blend_width_deg))
            self._band = self.builder.band
        else:
            self._map = self.builder.build_fast(roll, pitch)
            self._band = self.builder.band
        self._fixed = None
        self._frames_on_map = 0
        self._tilt = tilt_matrix(roll, pitch, self.builder.imu_to_camera)
        self.attitude = (roll, pitch)
        self.rebuild_count += 1
        self.last_rebuild_s = time.perf_counter() - start
        return True

    # -- images ---------------------------------------------------------------------------
    def mosaic_view(self, index: int) -> np.ndarray:
        """Return the mosaic region of camera ``index`` (a writable view)."""
        cam = self.rig.cameras[index]
        x0, y0 = self.builder.layout.offsets[index]
        return self.mosaic[y0:y0 + cam.height, x0:x0 + cam.width]

    def set_image(self, index: int, image: np.ndarray) -> None:
        """
        Copy camera ``index``'s image (uint8, HxW or HxWx3) into the mosaic.

        Raises :class:`InputError` naming the camera when the size or type is wrong.
        Grey images are expanded to three channels for a colour stitcher and colour
        images (BGR order assumed) converted to grey for a grey one.
        """
        self._copy_in(index, self._checked_image(index, image))

    def _checked_image(self, index, image):
        """Return ``image`` as an HxW or HxWx3 uint8 array, or raise naming the camera."""
        cam = self.rig.cameras[index]
        image = np.asarray(image)
        if image.dtype != np.uint8:
            raise InputError(f'camera {index} ({cam.name!r}): expected 8-bit images, got '
                             f'{image.dtype}')
        if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (1, 3)):
            raise InputError(f'camera {index} ({cam.name!r}): expected an HxW or HxWx3 '
                             f'image, got shape {image.shape}')
        if image.shape[:2] != (cam.height, cam.width):
            raise InputError(f'camera {index} ({cam.name!r}): image is '
                             f'{image.shape[1]}x{image.shape[0]}, the rig file says '
                             f'{cam.width}x{cam.height}')
        return image[:, :, 0] if image.ndim == 3 and image.shape[2] == 1 else image

    def _copy_in(self, index, image):
        """Copy a checked image into the mosaic (None blacks the camera out)."""
        view = self.mosaic_view(index)
        if image is None:
            view[...] = 0
        elif self.channels == 3 and image.ndim == 2:
            self._cv2.cvtColor(image, self._cv2.COLOR_GRAY2BGR, dst=view)
        elif self.channels == 1 and image.ndim == 3:
            view[...] = self._cv2.cvtColor(image, self._cv2.COLOR_BGR2GRAY)
        else:
            np.copyto(view, image)

    def _copy_all(self, images):
        for i, image in enumerate(images):
            self._copy_in(i, image)

    def update(self, roll: float, pitch: float, images: Sequence[np.ndarray]) -> bool:
        """
        Set the attitude (radians) and one image per rig camera (None: camera blacked out).

        Everything is checked before anything changes (:class:`InputError` otherwise).
        When the lookup has to be rebuilt, the images are copied into the mosaic by a
        worker thread meanwhile (the copies hold no lock numpy's work needs), so a
        changing attitude costs the rebuild alone. Returns True if the lookup was rebuilt.
        """
        if len(images) != len(self.rig):
            raise InputError(f'expected {len(self.rig)} images (one per rig camera, in rig '
                             f'order), got {len(images)}')
        roll, pitch = _finite_attitude(roll, pitch)
        checked = [None if image is None else self._checked_image(i, image)
                   for i, image in enumerate(images)]
        if not self.needs_rebuild(roll, pitch):
            self._copy_all(checked)
            return False
        if self._copy_pool is None:
            from concurrent.futures import ThreadPoolExecutor

            self._copy_pool = ThreadPoolExecutor(max_workers=1,
                                                 thread_name_prefix='mosaic_copy')
        copies = self._copy_pool.submit(self._copy_all, checked)
        try:
            return self.set_attitude(roll, pitch)
        finally:
            copies.result()

    def clear_image(self, index: int) -> None:
        """Black out camera ``index`` (a stalled camera leaves its sector black)."""
        self._copy_in(index, None)

    # -- output ---------------------------------------------------------------------------
    def render(self) -> np.ndarray:
        """
        Return the panorama of the current mosaic (an internal buffer: copy to keep it).

        Raises :class:`InputError` if no attitude was set yet.
        """
        cv2 = self._cv2
        if self._map is None and self._blend is None:
            raise InputError('no attitude yet: call set_attitude() before render()')
        r0, r1 = self._band
        out = self._out
        # Rows drawn by an earlier map but outside this band go black.
        d0, d1 = self._drawn
        if d0 < r0:
            out[d0:min(d1, r0)] = 0
        if d1 > r1:
            out[max(d0, r1):d1] = 0
        self._drawn = (r0, r1)
        if r1 <= r0:
            return out
        dst = out[r0:r1]
        if self._blend is not None:
            map1, map2, weight = self._blend
            first = cv2.remap(self.mosaic, map1[r0:r1], None, cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            second = cv2.remap(self.mosaic, map2[r0:r1], None, cv2.INTER_LINEAR,
                               borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            w = np.ascontiguousarray(weight[r0:r1])
            dst[...] = cv2.blendLinear(first, second, w, 1.0 - w)
            return out
        fine = self._map
        assert fine is not None  # no blend: set_attitude built the map
        self._frames_on_map += 1
        if self._fixed is None and self._frames_on_map >= 2:
            self._fixed = cv2.convertMaps(fine[r0:r1], None, cv2.CV_16SC2)
        if self._fixed is not None:
            cv2.remap(self.mosaic, self._fixed[0], self._fixed[1], cv2.INTER_LINEAR, dst=dst,
                      borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        else:
            cv2.remap(self.mosaic, fine[r0:r1], None, cv2.INTER_LINEAR, dst=dst,
                      borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        return out

    def stitch(self, images: Sequence[np.ndarray], roll: float, pitch: float) -> np.ndarray:
        """Set the attitude and every image, and return a copy of the panorama."""
        self.update(roll, pitch, images)
        return self.render().copy()

    def coverage(self) -> np.ndarray:
        """
        Return the mask of panorama pixels some camera sees with the current map.

        A pixel counts as seen when at least half of its bilinear weight falls on camera
        pixels (the outermost half pixel of a frame fades to black).
        """
        cv2 = self._cv2
        if self._map is None and self._blend is None:
            raise InputError('no attitude yet')
        white = np.zeros(self.mosaic.shape[:2], np.uint8)
        for i, cam in enumerate(self.rig.cameras):
            x0, y0 = self.builder.layout.offsets[i]
            white[y0:y0 + cam.height, x0:x0 + cam.width] = 255
        mask = np.zeros(self.geometry.shape, bool)
        r0, r1 = self._band
        maps: List[np.ndarray] = [m for m in ([self._map] if self._blend is None
                                              else self._blend[:2]) if m is not None]
        for m in maps:
            seen = cv2.remap(white, m[r0:r1], None, cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            mask[r0:r1] |= seen >= 128
        return mask
