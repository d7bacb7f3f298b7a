"""
Synthetic ground truth: an equirectangular scene, camera views of it, its true panorama.

The scene is an equirectangular texture over the whole sphere of the *level* frame
(REP-103: x forward, y left, z up): column 0's left edge at azimuth -180 deg, the top
edge at elevation +90 deg, pixel centres at half steps (as in :mod:`.projection`);
azimuth is positive to the right (``az = atan2(-y, x)``). The horizon (elevation 0) is
a sharp edge between a uniform sky band and a uniform ground band ``band_deg`` wide
(for sub-pixel horizon detection); beyond the bands the sky has smooth clouds and posts
every 30 deg of azimuth, the ground a multi-scale texture and a grid of lines.

:func:`render_camera_views` renders what each camera of a rig sees for a given attitude
(pinhole + OpenCV distortion, inverted by Newton's method), sampling the texture
bilinearly; :func:`render_panorama_truth` samples the same texture straight into the
panorama geometry, i.e. what a perfect stitcher with the true attitude would produce.
"""
from typing import Any, List, Optional

from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rot_z, rotation_from_rpy_radians
from accelcal_ros.panorama.rig_projection import normalized_from_pixels, reference_heading_rad
import numpy as np

SKY_BGR = (235, 205, 170)
GROUND_BGR = (70, 100, 85)


def _smooth_noise(rng, shape, cells, cv2):
    """Return smooth noise in [-1, 1] of ``shape`` from a ``cells`` grid, wrapping in x."""
    coarse = rng.normal(0.0, 1.0, (cells[0], cells[1])).astype(np.float32)
    coarse = np.concatenate([coarse, coarse[:, :1]], axis=1)
    width = shape[1] + shape[1] // cells[1]
    big = cv2.resize(coarse, (width, shape[0]), interpolation=cv2.INTER_CUBIC)[:, :shape[1]]
    return np.clip(big / 2.5, -1.0, 1.0)


def make_scene(width: int = 3600, height: int = 1800, seed: int = 0,
               band_deg: float = 6.0) -> np.ndarray:
    """
    Return the equirectangular test scene, uint8 BGR ``(height, width, 3)``.

    ``height`` must be even so that the horizon falls exactly between two rows.
    """
    import cv2

    if height % 2:
        raise ValueError('scene height must be even (horizon between two rows)')
    rng = np.random.default_rng(seed)
    el = 90.0 - 180.0 * (np.arange(height) + 0.5) / height
    az = -180.0 + 360.0 * (np.arange(width) + 0.5) / width
    el_grid = el[:, None] * np.ones((1, width))
    az_grid = np.ones((height, 1)) * az[None, :]
    scene = np.empty((height, width, 3), np.float32)
    clouds = _smooth_noise(rng, (height, width), (18, 72), cv2)
    fine = _smooth_noise(rng, (height, width), (90, 360), cv2)
    sky = el_grid > 0
    for c in range(3):
        sky_value = SKY_BGR[c] - 40.0 * np.clip(el_grid / 90.0, 0, 1) + 30.0 * clouds
        ground_value = GROUND_BGR[c] + 35.0 * fine + 20.0 * clouds
        scene[..., c] = np.where(sky, sky_value, ground_value)
    lines = ((np.abs(((az_grid + 5.0) % 10.0) - 5.0) < 0.15)
             | (np.abs(((el_grid + 2.5) % 5.0) - 2.5) < 0.15)) & ~sky
    scene[lines] *= 0.45
    posts = (np.abs(((az_grid + 15.0) % 30.0) - 15.0) < 0.6) & (el_grid > band_deg) \
        & (el_grid < band_deg + 8.0)
    scene[posts] = (40.0, 40.0, 60.0)
    band = np.abs(el_grid) < band_deg
    scene[band & sky] = SKY_BGR
    scene[band & ~sky] = GROUND_BGR
    return np.clip(np.rint(scene), 0, 255).astype(np.uint8)


def sample_scene(scene: np.ndarray, directions_level: np.ndarray) -> np.ndarray:
    """Colours of the scene seen along level-frame unit vectors ``(..., 3)`` (bilinear)."""
    import cv2

    d = np.asarray(directions_level, dtype=np.float64)
    height, width = scene.shape[:2]
    az = np.arctan2(-d[..., 1], d[..., 0])
    el = np.arcsin(np.clip(d[..., 2] / np.linalg.norm(d, axis=-1), -1.0, 1.0))
    col = ((az / (2.0 * np.pi) + 0.5) * width - 0.5).astype(np.float32)
    row = ((0.5 - el / np.pi) * height - 0.5).astype(np.float32)
    return cv2.remap(scene, col, row, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)


def camera_to_level(rig: Any, index: int, roll: float, pitch: float,
                    imu_to_camera: np.ndarray = DEFAULT_IMU_TO_CAMERA) -> np.ndarray:
    """Rotation taking camera ``index``'s optical-frame vectors into the level frame."""
    c = np.asarray(imu_to_camera, dtype=float).reshape(3, 3)
    return rotation_from_rpy_radians(roll, pitch) @ c.T @ rig.cameras[index].R.T


def render_camera_views(scene: np.ndarray, rig: Any, roll: float, pitch: float,
                        imu_to_camera: np.ndarray = DEFAULT_IMU_TO_CAMERA) -> List[np.ndarray]:
    """
    Render every camera's image of ``scene`` for the body attitude ``(roll, pitch)`` (rad).

    Ray of camera pixel ``(x, y)``: undistorted normalized coordinates ``[xn, yn, 1]``
    -> reference camera (``R_0i^T``) -> body (``C^T``) -> level (``R_bl``).
    """
    images = []
    for i, cam in enumerate(rig.cameras):
        ys, xs = np.mgrid[0:cam.height, 0:cam.width].astype(np.float64)
        xn, yn = normalized_from_pixels(cam, xs, ys)
        rays = np.stack([xn, yn, np.ones_like(xn)], axis=-1)
        level = rays @ camera_to_level(rig, i, roll, pitch, imu_to_camera).T
        images.append(sample_scene(scene, level))
    return images


def panorama_frame_to_level(imu_to_camera: np.ndarray = DEFAULT_IMU_TO_CAMERA) -> np.ndarray:
    """Rotation taking panorama-frame rays into the level frame: ``R_z(psi_0) C_0^T``."""
    return rot_z(reference_heading_rad(imu_to_camera)) @ DEFAULT_IMU_TO_CAMERA.T


def render_panorama_truth(scene: np.ndarray, geometry: Any,
                          imu_to_camera: np.ndarray = DEFAULT_IMU_TO_CAMERA) -> np.ndarray:
    """Return the scene sampled straight into the panorama geometry (the ideal result)."""
    rays = geometry.rays(np.arange(geometry.width)[None, :],
                         np.arange(geometry.height)[:, None])
    return sample_scene(scene, rays @ panorama_frame_to_level(imu_to_camera).T)


def horizon_rows(panorama: np.ndarray, geometry: Any, search_deg: float = 3.5,
                 expected_row: Optional[float] = None) -> np.ndarray:
    """
    Sub-pixel row of the sky/ground edge in each column (NaN where not seen).

    Searches ``search_deg`` of elevation around ``expected_row`` (default: the true
    horizon row) for the first crossing, from the top, of the level midway between the
    sky and ground colours of :func:`make_scene`; a column counts only where the sky
    above and the ground below the crossing are both covered (not black).
    """
    grey = np.asarray(panorama, dtype=np.float32)
    if grey.ndim == 3:
        grey = grey.mean(axis=2)
    sky, ground = float(np.mean(SKY_BGR)), float(np.mean(GROUND_BGR))
    threshold = 0.5 * (sky + ground)
    centre = geometry.horizon_row() if expected_row is None else expected_row
    reach = int(np.ceil(np.radians(search_deg) * geometry.pixels_per_radian_vertical()))
    r0 = max(0, int(np.floor(centre)) - reach)
    r1 = min(geometry.height, int(np.ceil(centre)) + reach + 1)
    window = grey[r0:r1]
    below = window < threshold
    first = np.argmax(below, axis=0)
    cols = np.arange(window.shape[1])
    prev = np.maximum(first - 1, 0)
    after = np.minimum(first + 1, window.shape[0] - 1)
    upper, lower = window[prev, cols], window[first, cols]
    valid = below[first, cols] & (first > 0) & (upper > threshold)
    valid &= (lower > 0.5 * ground) & (window[after, cols] > 0.5 * ground)
    with np.errstate(divide='ignore', invalid='ignore'):
        frac = (upper - threshold) / (upper - lower)
    rows = r0 + prev + frac
    return np.where(valid, rows, np.nan)


def psnr(a: np.ndarray, b: np.ndarray, mask: Optional[np.ndarray] = None) -> float:
    """Peak signal-to-noise ratio (dB, 8-bit) of two images over ``mask`` (all if None)."""
    diff = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    if diff.ndim == 3:
        diff = diff.reshape(diff.shape[0], diff.shape[1], -1)
        err = (diff ** 2).mean(axis=2)
    else:
        err = diff ** 2
    mse = err[mask].mean() if mask is not None else err.mean()
    return float('inf') if mse == 0 else float(10.0 * np.log10(255.0 ** 2 / mse))
