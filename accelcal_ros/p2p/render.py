"""
Rendered ground truth: images of the two emitters at known poses (pure core).

The emitters are projected with the camera model (:class:`accelcal_ros.camera.CameraModel`,
OpenCV's; object to camera ``X_cam = R X_obj + t``) and drawn as Gaussian spots
(``sigma_px``, ``peak`` grey level, saturating at 255) on a dark background, then
optionally blurred (Gaussian, ``blur_sigma_px``, e.g. defocus) and given additive
Gaussian noise (``noise_std``), quantised to 8 bits. Pixel centres are at integer
coordinates (OpenCV). Deterministic for a given ``seed``.
"""
from typing import Sequence, Tuple

from accelcal_ros.camera import CameraModel
from accelcal_ros.errors import InputError
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rotation_from_rpy_radians
import numpy as np
from numpy.typing import ArrayLike


def pose_from_camera_attitude(roll: float, pitch: float, yaw: float, position: Sequence[float],
                              imu_to_camera: np.ndarray = DEFAULT_IMU_TO_CAMERA
                              ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return ``(R, t)`` (object to camera) of a camera body at REP-103 roll/pitch/yaw (rad).

    The camera body (x forward along the optical axis when mounted with the default
    ``imu_to_camera``) has attitude ``Rz(yaw) Ry(pitch) Rx(roll)`` in the object frame and
    its centre at ``position`` (object frame, m): ``R = imu_to_camera R_body^T``,
    ``t = -R position``.
    """
    body = rotation_from_rpy_radians(roll, pitch, yaw)
    r = np.asarray(imu_to_camera, dtype=float) @ body.T
    return r, -r @ np.asarray(position, dtype=float)


def project(points: np.ndarray, rotation: np.ndarray, translation: np.ndarray,
            camera: CameraModel) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the distorted pixels ``(N, 2)`` and depths ``(N,)`` (m) of object points ``(N, 3)``.

    Points behind the camera (depth <= 0) have NaN pixels.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    in_camera = points @ np.asarray(rotation, dtype=float).T + np.asarray(
        translation, dtype=float).reshape(3)
    return camera.project(in_camera), in_camera[:, 2]


def draw_spots(shape: Tuple[int, int], uv: ArrayLike, sigma_px: float = 1.5,
               peak: float = 230.0, background: float = 8.0) -> np.ndarray:
    """Return a float image of Gaussian spots of ``sigma_px`` at sub-pixel ``uv`` ``(N, 2)``."""
    height, width = shape
    image = np.full((height, width), float(background))
    radius = int(np.ceil(5.0 * sigma_px)) + 1
    for u, v in np.asarray(uv, dtype=float).reshape(-1, 2):
        u0, v0 = int(round(u)), int(round(v))
        x0, x1 = max(u0 - radius, 0), min(u0 + radius + 1, width)
        y0, y1 = max(v0 - radius, 0), min(v0 + radius + 1, height)
        if x0 >= x1 or y0 >= y1:
            continue
        xs = np.arange(x0, x1) - u
        ys = np.arange(y0, y1) - v
        spot = np.exp(-0.5 * (ys[:, None] ** 2 + xs[None, :] ** 2) / sigma_px ** 2)
        image[y0:y1, x0:x1] += peak * spot
    return image


def render_emitters(points: ArrayLike, rotation: np.ndarray, translation: ArrayLike,
                    camera: CameraModel, sigma_px: float = 1.5, peak: float = 230.0,
                    background: float = 8.0, blur_sigma_px: float = 0.0,
                    noise_std: float = 2.0, seed: int = 0, extra_uv: ArrayLike = ()
                    ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Render the emitters ``points`` ``(N, 3)`` (object frame) seen at pose ``(R, t)``.

    Returns ``(image, uv, depth)``: the uint8 ``height x width`` image, the true distorted
    pixel coordinates ``(N, 2)`` of the emitters and their depths. ``extra_uv`` adds
    distractor spots (reflections) at those pixels. Emitters behind the camera are not
    drawn. Raises :class:`InputError` for a non-positive ``sigma_px``.
    """
    import cv2

    if sigma_px <= 0:
        raise InputError(f'sigma_px must be positive, got {sigma_px}')
    uv, depth = project(np.asarray(points, dtype=float), rotation,
                        np.asarray(translation, dtype=float), camera)
    visible = uv[depth > 0.0]
    extra = np.asarray(extra_uv, dtype=float).reshape(-1, 2)
    if len(extra):
        visible = np.concatenate([visible, extra])
    image = draw_spots((camera.height, camera.width), visible, sigma_px, peak, background)
    if blur_sigma_px > 0:
        image = cv2.GaussianBlur(image, (0, 0), blur_sigma_px)
    if noise_std > 0:
        rng = np.random.default_rng(seed)
        image += rng.standard_normal(image.shape, dtype=np.float32) * noise_std
    return np.clip(np.rint(image), 0, 255).astype(np.uint8), uv, depth
