"""
Find the two emitters of the P2P target in an image (pure core: numpy + OpenCV).

Pipeline: grey image -> fixed threshold -> 8-connected components
(``cv2.connectedComponentsWithStats``) -> size and brightness limits -> intensity-weighted
sub-pixel centroids -> exactly two candidates required -> ordering (which blob is M1)
-> undistortion by the camera model (:class:`accelcal_ros.camera.CameraModel`: ROS
``plumb_bob``/``rational_polynomial`` and ``equidistant`` models).

Pixel convention (OpenCV): the centre of pixel (column u, row v) is at ``(u, v)``.
Centroid weights are ``I - threshold + 1`` over the component's pixels, so the dim rim
that crosses the threshold counts little and a symmetric blob gives an unbiased centre.

Zero, one or three-plus candidates give no detection, with a reason that says what to
change (:attr:`BeaconDetection.reason`).
"""
from dataclasses import dataclass, field
from typing import Any, Dict, Optional, Tuple

from accelcal_ros.camera import CameraModel
from accelcal_ros.errors import InputError
import numpy as np

ORDERS = ('left_to_right', 'right_to_left', 'top_to_bottom', 'bottom_to_top',
          'larger_first', 'smaller_first', 'brighter_first', 'dimmer_first')
"""How M1 is told from M2. ``left_to_right``: M1 is the left emitter as seen by the
camera, gravity-aware when ``down`` is given (left/right of the horizon, so a rolled
camera keeps the order), else by image column. ``larger_first``/``brighter_first``: M1
is the blob with more pixels / more total intensity."""


@dataclass(frozen=True)
class DetectorSettings:
    """
    Detection limits.

    ``threshold`` (grey level 0..255): pixels above it are candidate emitter pixels;
    ``min_area_px``/``max_area_px``: blob size limits (pixels); ``min_peak``: the
    brightest pixel of a blob must reach it (0: no limit); ``max_candidates``: give up
    (reason: too many candidates) beyond this many blobs within the limits;
    ``order``: one of :data:`ORDERS`.
    """

    threshold: int = 160
    min_area_px: int = 2
    max_area_px: int = 5000
    min_peak: int = 0
    max_candidates: int = 50
    order: str = 'left_to_right'

    def __post_init__(self):
        """Check ranges with reasons that name the setting."""
        if not 0 <= self.threshold <= 254:
            raise InputError(f'threshold: {self.threshold} is outside 0..254')
        if self.min_area_px < 1 or self.max_area_px < self.min_area_px:
            raise InputError(f'blob area limits: need 1 <= min_area_px <= max_area_px, got '
                             f'{self.min_area_px}..{self.max_area_px}')
        if not 0 <= self.min_peak <= 255:
            raise InputError(f'min_peak: {self.min_peak} is outside 0..255')
        if self.order not in ORDERS:
            raise InputError(f'order: {self.order!r} is not one of {", ".join(ORDERS)}')


@dataclass(frozen=True)
class Blob:
    """One candidate: sub-pixel centroid (px), area (px), peak and summed intensity."""

    u: float
    v: float
    area: int
    peak: int
    flux: float
    saturated_px: int
    elongation: float

    def as_dict(self) -> Dict[str, Any]:
        """Return the blob as a plain dict (for JSON and diagnostics)."""
        return {'u': self.u, 'v': self.v, 'area': self.area, 'peak': self.peak,
                'flux': self.flux, 'saturated_px': self.saturated_px,
                'elongation': self.elongation}


@dataclass
class BeaconDetection:
    """
    Result of :func:`detect_beacons`.

    ``ok``: exactly two emitters found; then ``uv`` ``(2, 2)`` holds the raw (distorted)
    pixel centroids of M1 and M2, ``uv_undistorted`` ``(2, 2)`` the undistorted pixels
    and ``rays`` ``(2, 3)`` the normalised rays ``[x, y, 1]`` (both only when a camera
    matrix was given). ``blobs``: the candidates within the limits (ordered M1, M2 when
    ok); ``rejected``: counts of components dropped per limit; ``reason``: why there is
    no detection (``''`` when ok).
    """

    ok: bool
    reason: str
    blobs: list = field(default_factory=list)
    rejected: dict = field(default_factory=dict)
    brightest: int = 0
    uv: Optional[np.ndarray] = None
    uv_undistorted: Optional[np.ndarray] = None
    rays: Optional[np.ndarray] = None

    def quality(self) -> Dict[str, Any]:
        """Return a flat dict of quality figures (diagnostics key/values)."""
        out: Dict[str, Any] = {'candidates': len(self.blobs), 'brightest': self.brightest}
        out.update({f'rejected_{k}': v for k, v in self.rejected.items()})
        for index, blob in enumerate(self.blobs[:2] if self.ok else []):
            name = f'M{index + 1}'
            out[f'{name}_area_px'] = blob.area
            out[f'{name}_peak'] = blob.peak
            out[f'{name}_saturated_px'] = blob.saturated_px
            out[f'{name}_elongation'] = round(blob.elongation, 3)
        if self.ok and self.uv is not None:
            out['separation_px'] = float(np.hypot(*(self.uv[0] - self.uv[1])))
        return out


def to_grey(image: np.ndarray) -> np.ndarray:
    """Return a 2-D uint8 grey image from mono8 (HxW) or 3-channel (HxWx3) uint8 input."""
    import cv2

    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise InputError(f'expected an 8-bit image, got dtype {image.dtype}')
    if image.ndim == 2:
        return image
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if image.ndim == 3 and image.shape[2] == 1:
        return image[:, :, 0]
    raise InputError(f'expected an HxW or HxWx3 image, got shape {image.shape}')


def find_blobs(grey: np.ndarray, settings: DetectorSettings) -> Tuple[list, dict, int]:
    """
    Return ``(blobs, rejected, brightest)``: candidates within the limits and drop counts.

    Components are dropped as ``small`` / ``large`` (area), ``dim`` (peak below
    ``min_peak``); more than ``max_candidates`` survivors stops the centroiding.
    """
    import cv2

    brightest = int(grey.max()) if grey.size else 0
    rejected = {'small': 0, 'large': 0, 'dim': 0}
    if brightest <= settings.threshold:
        return [], rejected, brightest
    _, binary = cv2.threshold(grey, settings.threshold, 255, cv2.THRESH_BINARY)
    # Label only the bounding box of the bright pixels: emitters are sparse, so this is
    # usually a small fraction of the frame (same result, several times faster).
    left, top, width, height = cv2.boundingRect(binary)
    grey = grey[top:top + height, left:left + width]
    binary = binary[top:top + height, left:left + width]
    count, labels, stats, _ = cv2.connectedComponentsWithStats(binary, connectivity=8,
                                                               ltype=cv2.CV_32S)
    areas = stats[1:, cv2.CC_STAT_AREA]
    small = areas < settings.min_area_px
    large = areas > settings.max_area_px
    rejected['small'] = int(small.sum())
    rejected['large'] = int(large.sum())
    keep = np.nonzero(~small & ~large)[0] + 1
    blobs = []
    if len(keep) > settings.max_candidates:
        rejected['over_limit'] = int(len(keep))
        return [None] * len(keep), rejected, brightest
    for label in keep:
        fields = (cv2.CC_STAT_LEFT, cv2.CC_STAT_TOP, cv2.CC_STAT_WIDTH, cv2.CC_STAT_HEIGHT)
        x, y, w, h = (int(stats[label, i]) for i in fields)
        patch = grey[y:y + h, x:x + w]
        mask = labels[y:y + h, x:x + w] == label
        values = patch[mask]
        peak = int(values.max())
        if peak < settings.min_peak:
            rejected['dim'] += 1
            continue
        weights = values.astype(float) - (settings.threshold - 1)
        rows, cols = np.nonzero(mask)
        total = weights.sum()
        u = x + float((weights * cols).sum() / total)
        v = y + float((weights * rows).sum() / total)
        du, dv = cols + x - u, rows + y - v
        u, v = u + left, v + top
        cov = np.array([[(weights * du * du).sum(), (weights * du * dv).sum()],
                        [(weights * du * dv).sum(), (weights * dv * dv).sum()]]) / total
        eig = np.linalg.eigvalsh(cov)
        elongation = float(np.sqrt(eig[1] / eig[0])) if eig[0] > 1e-12 else float('inf')
        blobs.append(Blob(u, v, int(values.size), peak, float(values.astype(float).sum()),
                          int((values == 255).sum()), elongation))
    return blobs, rejected, brightest


def order_blobs(blobs: list, order: str, camera: Optional[CameraModel] = None,
                down: Optional[np.ndarray] = None) -> list:
    """
    Return the two blobs as (M1, M2) by ``order`` (:data:`ORDERS`).

    ``left_to_right`` with ``camera`` and ``down`` (camera optical frame) compares the
    rays along the camera's level "right" axis ``down x z`` (horizontal), so the order
    holds at any roll; without them it compares the image column u.
    """
    a, b = blobs
    if order in ('larger_first', 'smaller_first'):
        first = a if (a.area, a.flux) >= (b.area, b.flux) else b
        if order == 'smaller_first':
            first = b if first is a else a
    elif order in ('brighter_first', 'dimmer_first'):
        first = a if a.flux >= b.flux else b
        if order == 'dimmer_first':
            first = b if first is a else a
    elif order in ('top_to_bottom', 'bottom_to_top'):
        first = a if a.v <= b.v else b
        if order == 'bottom_to_top':
            first = b if first is a else a
    else:
        key_a, key_b = a.u, b.u
        if camera is not None and down is not None:
            right = np.cross(np.asarray(down, dtype=float), [0.0, 0.0, 1.0])
            if np.linalg.norm(right) > 1e-6 and np.all(np.isfinite(right)):
                x, y = camera.distorted_from_pixels(np.array([a.u, b.u]),
                                                    np.array([a.v, b.v]))
                key_a, key_b = (float(k) for k in right[0] * x + right[1] * y)
        first = a if key_a <= key_b else b
        if order == 'right_to_left':
            first = b if first is a else a
    second = b if first is a else a
    return [first, second]


def undistort_pixels(uv: np.ndarray, camera: CameraModel) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return ``(rays, uv_undistorted)`` of raw pixels ``uv`` ``(N, 2)`` of ``camera``.

    ``rays`` ``(N, 3)`` are normalised ``[x, y, 1]`` (optical frame);
    ``uv_undistorted`` ``(N, 2)`` the same points re-projected with ``K`` alone (ideal
    pinhole pixels). Raises :class:`InputError` for a pixel the lens model has no ray
    for (past the radius where the distortion folds back, or where its inverse does not
    converge: NaN from :mod:`accelcal_ros.camera.distortion`).
    """
    uv = np.asarray(uv, dtype=float).reshape(-1, 2)
    x, y = camera.normalized_from_pixels(uv[:, 0], uv[:, 1], iterations=20)
    lost = ~(np.isfinite(x) & np.isfinite(y)) & np.isfinite(uv).all(axis=1)
    if lost.any():
        u, v = uv[np.argmax(lost)]
        raise InputError(f"pixel ({u:g}, {v:g}) is outside the lens model's valid range "
                         f'(distortion D={camera.D.tolist()} has no ray there: it folds '
                         'back or does not invert); check D, or the detection')
    rays = np.stack([x, y, np.ones_like(x)], axis=1)
    return rays, (rays @ camera.K.T)[:, :2]


def detect_beacons(image: np.ndarray, settings: Optional[DetectorSettings] = None,
                   camera: Optional[CameraModel] = None,
                   down: Optional[np.ndarray] = None) -> BeaconDetection:
    """
    Detect the two emitters in ``image`` (uint8, grey or BGR); return a :class:`BeaconDetection`.

    With ``camera`` the result also has undistorted pixels and rays; ``down`` (camera
    optical frame) makes ``left_to_right`` ordering gravity-aware.
    """
    settings = settings or DetectorSettings()
    grey = to_grey(image)
    blobs, rejected, brightest = find_blobs(grey, settings)
    detection = BeaconDetection(False, '', blobs, rejected, brightest)
    limits = (f'threshold {settings.threshold}, area {settings.min_area_px}..'
              f'{settings.max_area_px} px, min_peak {settings.min_peak}')
    if 'over_limit' in rejected:
        detection.blobs = []
        detection.reason = (f'{rejected["over_limit"]} candidate blobs (more than '
                            f'max_candidates {settings.max_candidates}): raise the threshold '
                            f'(now {settings.threshold}) or shorten the exposure')
        return detection
    if not blobs:
        dropped = ', '.join(f'{v} {k}' for k, v in rejected.items() if v)
        if brightest <= settings.threshold:
            detection.reason = (f'no emitter: no pixel above threshold {settings.threshold} '
                                f'(brightest {brightest}); lower the threshold or check that '
                                f'the emitters are on and in view')
        else:
            detection.reason = (f'no emitter: no blob within the limits ({limits}); '
                                f'dropped: {dropped}')
        return detection
    if len(blobs) == 1:
        detection.reason = (f'one emitter candidate, need two ({limits}): the second emitter '
                            f'is out of view, occluded, too dim or merged with the first')
        return detection
    if len(blobs) > 2:
        detection.reason = (f'{len(blobs)} emitter candidates, need exactly two ({limits}): '
                            f'reflections or other lights; raise the threshold or min_peak, '
                            f'or tighten the area limits')
        return detection
    ordered = order_blobs(blobs, settings.order, camera, down)
    detection.blobs = ordered
    detection.uv = np.array([[b.u, b.v] for b in ordered])
    if camera is not None:
        try:
            detection.rays, detection.uv_undistorted = undistort_pixels(detection.uv, camera)
        except InputError as exc:  # an emitter where the lens model has no ray: no pose
            detection.reason = f'emitter {exc}'
            return detection
    detection.ok = True
    return detection
