r"""
Ground truth for rig calibration: a rig of known cameras photographing a chessboard.

Frames. World: level, z up (REP-103). IMU (body): x forward, y left, z up;
``R_wi`` maps IMU vectors to world, the IMU origin is at ``p`` (world, m). Reference
camera: ``v_cam0 = imu_to_camera v_imu``. Camera ``i``: ``R_ci = R_0i imu_to_camera``
(IMU -> optical), centre ``c_i`` (IMU frame, m), so ``X_i = R_ci (X_imu - c_i)`` and
``X_i = R_0i X_0 + t_0i`` with ``t_0i = R_ci (c_0 - c_i)``. Board: lies on a floor, its
frame (:mod:`.board`) has z into the paper, i.e. down, tilted by ``tilt_deg`` from level:
``R_wb = R_tilt diag(1, -1, -1)``; its centre is the world origin.

Images are rendered by ray casting through the OpenCV distortion model: every sub-pixel
sample is unprojected (``cv2.undistortPointsIter``, checked by reprojection), its ray
intersected with the board plane and given the square's brightness box-filtered over
the sample's footprint on the board (:meth:`.Board.reflectance`); ``supersample^2``
samples per pixel are averaged, so corners are sub-pixel exact.
The accelerometer reads the specific force ``f = R_wi^T [0, 0, g]`` (REP-145) plus
white noise.
"""
from dataclasses import dataclass, field
import functools
import os
from typing import Dict, List, Optional, Sequence, Tuple

from accelcal_ros.errors import InputError
from accelcal_ros.fileio import write_bytes_atomic
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rot_x, rot_y, rot_z
from accelcal_ros.rig.board import Board
from accelcal_ros.sensor.recording import save_recording
import cv2
import numpy as np

STANDARD_GRAVITY = 9.80665
BLACK_LEVEL = 30.0
WHITE_LEVEL = 220.0
BACKGROUND_LEVEL = 110.0


@dataclass
class RigTruth:
    """Known rig: per camera name, size, ``K``, ``D`` (5), ``R_0i``, centre; the IMU and board."""

    names: List[str]
    sizes: List[Tuple[int, int]]
    K: List[np.ndarray]
    D: List[np.ndarray]
    R: List[np.ndarray]
    centres_m: List[np.ndarray]
    imu_to_camera: np.ndarray
    board: Board
    board_tilt_deg: float
    board_tilt_azimuth_deg: float = 30.0
    gravity_m_s2: float = STANDARD_GRAVITY

    @property
    def board_to_world(self) -> np.ndarray:
        """``R_wb``: board frame (z into the paper) -> world (z up), tilted."""
        axis_az = np.radians(self.board_tilt_azimuth_deg)
        tilt = rot_z(axis_az) @ rot_x(np.radians(self.board_tilt_deg)) @ rot_z(-axis_az)
        return tilt @ np.diag([1.0, -1.0, -1.0])

    @property
    def board_up(self) -> np.ndarray:
        """World up (unit) in the board frame: ``R_wb^T e_z`` (near ``-e_z``)."""
        return self.board_to_world[2].copy()

    @property
    def board_origin_world(self) -> np.ndarray:
        """First inner corner in the world (m); the board's centre is the world origin."""
        return -self.board_to_world @ self.board.centre()

    def camera_rotation(self, index: int) -> np.ndarray:
        """``R_ci = R_0i imu_to_camera``: IMU -> camera ``index`` optical frame."""
        return self.R[index] @ self.imu_to_camera

    def translation(self, index: int) -> np.ndarray:
        """``t_0i`` (m): ``X_i = R_0i X_0 + t_0i``."""
        return self.camera_rotation(index) @ (self.centres_m[0] - self.centres_m[index])


@dataclass
class PoseTruth:
    """One still pose: IMU attitude ``R_wi`` (IMU -> world), position (m), who sees the board."""

    R_wi: np.ndarray
    position_m: np.ndarray
    visible: Tuple[int, ...] = field(default_factory=tuple)

    @property
    def specific_force(self) -> np.ndarray:
        """Return the unit specific force in the IMU frame (REP-145: up)."""
        return self.R_wi[2].copy()


def default_truth(tilt_deg: float = 0.4, seed: int = 0, width: int = 800, height: int = 600,
                  step_deg: float = 45.0, board: Optional[Board] = None,
                  focal_px: float = 425.0) -> RigTruth:
    """
    Return a 3-camera ring: camera 0 ahead, camera 1 ``step_deg`` right, camera 2 left.

    Each camera has its own focal length (about ``focal_px``: HFOV 87 deg at 800 px),
    principal point and barrel distortion; the non-reference cameras carry ~1 deg mount
    errors and ``imu_to_camera`` differs from the nominal one by a few degrees.
    """
    rng = np.random.default_rng(seed)
    names = ['cam0', 'cam1', 'cam2']
    azimuths = [0.0, step_deg, -step_deg]
    ks, ds, rs, centres = [], [], [], []
    for i, az in enumerate(azimuths):
        f = focal_px + rng.uniform(-10.0, 10.0)
        k = np.array([[f, 0.0, (width - 1) / 2.0 + rng.uniform(-6, 6)],
                      [0.0, f * (1.0 + rng.uniform(-0.003, 0.003)),
                       (height - 1) / 2.0 + rng.uniform(-6, 6)],
                      [0.0, 0.0, 1.0]])
        ks.append(k)
        ds.append(np.array([-0.18 + rng.uniform(-0.03, 0.03), 0.04 + rng.uniform(-0.01, 0.01),
                            rng.uniform(-5e-4, 5e-4), rng.uniform(-5e-4, 5e-4), 0.0]))
        r = rot_y(np.radians(az)).T
        if i:
            e = np.radians(rng.normal(0.0, 1.0, 3))
            r = rot_z(e[0]) @ rot_x(e[1]) @ rot_y(e[2]) @ r
        rs.append(r)
        body_az = -np.radians(az)
        centres.append(np.array([0.06 * np.cos(body_az), 0.06 * np.sin(body_az),
                                 0.01 * i]))
    mount = rot_z(np.radians(2.0)) @ rot_y(np.radians(-1.5)) @ rot_x(np.radians(1.2))
    imu_to_camera = DEFAULT_IMU_TO_CAMERA @ mount
    return RigTruth(names, [(width, height)] * 3, ks, ds, rs, centres, imu_to_camera,
                    board or Board(11, 8, 0.025), tilt_deg)


def board_in_camera(truth: RigTruth, pose: PoseTruth,
                    index: int) -> Tuple[np.ndarray, np.ndarray]:
    """Return ``(R_cb, t_cb)``: board frame -> camera ``index`` optical frame (m)."""
    r_ci = truth.camera_rotation(index)
    r_cw = r_ci @ pose.R_wi.T
    t_cw = -r_cw @ pose.position_m - r_ci @ truth.centres_m[index]
    return r_cw @ truth.board_to_world, r_cw @ truth.board_origin_world + t_cw


@functools.lru_cache(maxsize=64)
def _bounds_cached(k: Tuple[float, ...], d: Tuple[float, ...],
                   size: Tuple[int, ...]) -> np.ndarray:
    w, h = size
    k_matrix = np.array(k).reshape(3, 3)
    d_coeffs = np.array(d)
    u = np.linspace(0, w - 1, 33)
    v = np.linspace(0, h - 1, 25)
    border = np.concatenate([np.stack([u, np.zeros_like(u)], 1),
                             np.stack([u, np.full_like(u, h - 1)], 1),
                             np.stack([np.zeros_like(v), v], 1),
                             np.stack([np.full_like(v, w - 1), v], 1)])
    xy = _undistort(border, k_matrix, d_coeffs)
    return np.array([xy[:, 0].min(), xy[:, 0].max(), xy[:, 1].min(), xy[:, 1].max()])


def _normalised_bounds(truth: RigTruth, index: int) -> np.ndarray:
    # Normalised image coordinates (x/z, y/z) the image border reaches: min/max x, y.
    return _bounds_cached(tuple(truth.K[index].ravel()), tuple(truth.D[index]),
                          tuple(truth.sizes[index]))


def _undistort(pixels: np.ndarray, k: np.ndarray, d: np.ndarray) -> np.ndarray:
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 1e-12)
    pts = np.ascontiguousarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
    if hasattr(cv2, 'undistortPointsIter'):  # OpenCV 4.x
        out = cv2.undistortPointsIter(pts, k, d, None, None, criteria)
    else:  # OpenCV 5: undistortPoints takes the criteria
        out = cv2.undistortPoints(pts, k, d, None, None, None, criteria)
    return out.reshape(-1, 2)


def sees_board(truth: RigTruth, pose: PoseTruth, index: int, margin_px: float = 4.0,
               max_view_angle_deg: float = 65.0) -> bool:
    """Return True if camera ``index`` sees the whole printed board at a fair angle."""
    r_cb, t_cb = board_in_camera(truth, pose, index)
    pts = truth.board.outline_points(0.7) @ r_cb.T + t_cb
    if np.any(pts[:, 2] < 0.05):
        return False
    normal = r_cb[:, 2]
    to_board = (r_cb @ truth.board.centre() + t_cb)
    cos_view = normal @ to_board / np.linalg.norm(to_board)
    if cos_view < np.cos(np.radians(max_view_angle_deg)):
        return False
    xy = pts[:, :2] / pts[:, 2:]
    lo_x, hi_x, lo_y, hi_y = _normalised_bounds(truth, index)
    if np.any(xy[:, 0] < lo_x) or np.any(xy[:, 0] > hi_x) or np.any(xy[:, 1] < lo_y) \
            or np.any(xy[:, 1] > hi_y):
        return False
    px, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), truth.K[index], truth.D[index])
    px = px.reshape(-1, 2)
    w, h = truth.sizes[index]
    return bool(np.all(px >= margin_px) and np.all(px[:, 0] <= w - 1 - margin_px)
                and np.all(px[:, 1] <= h - 1 - margin_px))


def _axis_azimuth(truth: RigTruth, index: int) -> float:
    axis = truth.imu_to_camera.T @ truth.R[index][2]
    return float(np.arctan2(axis[1], axis[0]))


def plan_poses(truth: RigTruth, count: int = 30, seed: int = 1,
               targets: Optional[Sequence[Tuple[int, ...]]] = None,
               heading_span_deg: float = 360.0) -> List[PoseTruth]:
    """
    Draw ``count`` still poses, each showing the whole board to a target camera or pair.

    Targets cycle through single cameras and neighbouring pairs (``targets`` overrides).
    A pose looks down at the board at 35-65 deg below the horizon, rolled up to +-55 deg
    about the line of sight, at a random heading within ``heading_span_deg`` (0: the rig
    never turns about the vertical).
    """
    rng = np.random.default_rng(seed)
    n_cam = len(truth.names)
    if targets is None:
        targets = [(i,) for i in range(n_cam)] + [(0, i) for i in range(1, n_cam)]
    poses = []
    for k in range(count):
        target = tuple(targets[k % len(targets)])
        azs = [_axis_azimuth(truth, i) for i in target]
        base_az = float(np.arctan2(np.mean(np.sin(azs)), np.mean(np.cos(azs))))
        single = len(target) == 1
        for _ in range(500):
            az = base_az + np.radians(rng.uniform(-22, 22) if single else rng.uniform(-4, 4))
            up = np.radians(rng.uniform(-18, 18) if single else rng.uniform(-8, 8))
            el = np.radians(rng.uniform(35.0, 65.0))
            roll = np.radians(rng.uniform(-55.0, 55.0))
            heading = np.radians(rng.uniform(-0.5, 0.5) * heading_span_deg)
            r_wi = rot_z(heading) @ rot_y(el) @ rot_x(roll) @ rot_y(up) @ rot_z(-az)
            dist = rng.uniform(0.28, 0.5) if single else rng.uniform(0.5, 0.7)
            d_body = np.array([np.cos(az) * np.cos(up), np.sin(az) * np.cos(up), np.sin(up)])
            centre = np.mean([truth.centres_m[i] for i in target], axis=0)
            shift = rng.uniform(-0.03, 0.03, 3) * (1.0 if single else 0.3)
            position = -dist * (r_wi @ d_body) - r_wi @ centre + shift
            pose = PoseTruth(r_wi, position)
            seen = tuple(i for i in range(n_cam) if sees_board(truth, pose, i))
            if all(i in seen for i in target):
                pose.visible = seen
                poses.append(pose)
                break
        else:
            raise InputError(f'could not place a board view for cameras {target}')
    return poses


def _footprint(coord: np.ndarray) -> np.ndarray:
    # Extent of one sample's square footprint along a board coordinate (m), flattened.
    if min(coord.shape) < 2:
        return np.zeros(coord.size)
    d_row, d_col = np.gradient(coord)
    return np.nan_to_num(np.abs(d_row) + np.abs(d_col)).ravel()


class Renderer:
    """Ray-casting renderer with the per-camera rays cached (``supersample^2`` per pixel)."""

    def __init__(self, truth: RigTruth, supersample: int = 1) -> None:
        """Unproject every sub-pixel sample of every camera once."""
        self.truth = truth
        self.supersample = int(supersample)
        self._rays = [self._camera_rays(i) for i in range(len(truth.names))]

    def _camera_rays(self, index: int) -> np.ndarray:
        # Unproject pixel centres exactly, then each sub-pixel sample to first order with
        # the local Jacobian of the unprojection (central differences between pixels; the
        # second-order term is far below 1e-4 px at these distortions).
        w, h = self.truth.sizes[index]
        s = self.supersample
        k, d = self.truth.K[index], self.truth.D[index]
        v, u = np.mgrid[-1:h + 1, -1:w + 1].astype(np.float64)
        pixels = np.stack([u.ravel(), v.ravel()], axis=1)
        xy = _undistort(pixels, k, d)
        back, _ = cv2.projectPoints(np.column_stack([xy, np.ones(len(xy))]), np.zeros(3),
                                    np.zeros(3), k, d)
        bad = np.linalg.norm(back.reshape(-1, 2) - pixels, axis=1) > 1e-3
        xy[bad] = np.nan
        grid = xy.reshape(h + 2, w + 2, 2)
        centre = grid[1:-1, 1:-1]
        d_du = (grid[1:-1, 2:] - grid[1:-1, :-2]) / 2.0
        d_dv = (grid[2:, 1:-1] - grid[:-2, 1:-1]) / 2.0
        offsets = (np.arange(s) + 0.5) / s - 0.5
        rays = (centre[:, None, :, None, :]
                + offsets[None, None, None, :, None] * d_du[:, None, :, None, :]
                + offsets[None, :, None, None, None] * d_dv[:, None, :, None, :])
        return rays.astype(np.float32)

    def _board_box(self, r_cb: np.ndarray, t_cb: np.ndarray, index: int):
        # Pixel box (v0, v1, u0, u1) holding the printed board, or None for the full image.
        corners = self.truth.board.outline_points(1.2)
        edge = np.linspace(0.0, 1.0, 12)[:, None]
        outline = np.concatenate([corners[k] + edge * (corners[(k + 1) % 4] - corners[k])
                                  for k in range(4)])
        pts = outline @ r_cb.T + t_cb
        if np.any(pts[:, 2] < 0.02):
            return None
        xy = pts[:, :2] / pts[:, 2:]
        lo_x, hi_x, lo_y, hi_y = _normalised_bounds(self.truth, index)
        # bbox(board) intersected with the image's normalised box holds what is seen
        x0, x1 = max(xy[:, 0].min(), lo_x), min(xy[:, 0].max(), hi_x)
        y0, y1 = max(xy[:, 1].min(), lo_y), min(xy[:, 1].max(), hi_y)
        if x0 >= x1 or y0 >= y1:
            return 0, 0, 0, 0
        side = np.linspace(0.0, 1.0, 16)
        ring = np.concatenate([np.stack([x0 + side * (x1 - x0), np.full(16, y0)], 1),
                               np.stack([x0 + side * (x1 - x0), np.full(16, y1)], 1),
                               np.stack([np.full(16, x0), y0 + side * (y1 - y0)], 1),
                               np.stack([np.full(16, x1), y0 + side * (y1 - y0)], 1)])
        px, _ = cv2.projectPoints(np.column_stack([ring, np.ones(len(ring))]), np.zeros(3),
                                  np.zeros(3), self.truth.K[index], self.truth.D[index])
        px = px.reshape(-1, 2)
        w, h = self.truth.sizes[index]
        u0, v0 = np.floor(px.min(axis=0)).astype(int) - 3
        u1, v1 = np.ceil(px.max(axis=0)).astype(int) + 4
        return max(v0, 0), min(v1, h), max(u0, 0), min(u1, w)

    def render(self, pose: PoseTruth, index: int, noise_std: float = 1.0,
               rng: Optional[np.random.Generator] = None) -> np.ndarray:
        """Return the 8-bit grey image camera ``index`` takes in ``pose``."""
        truth = self.truth
        w, h = truth.sizes[index]
        s = self.supersample
        r_cb, t_cb = board_in_camera(truth, pose, index)
        origin = -r_cb.T @ t_cb
        image = np.full((h, w), BACKGROUND_LEVEL)
        box = self._board_box(r_cb, t_cb, index)
        v0, v1, u0, u1 = box if box is not None else (0, h, 0, w)
        if v1 > v0 and u1 > u0:
            xy = self._rays[index][v0:v1, :, u0:u1, :, :].reshape(-1, 2)
            d = xy.astype(np.float64) @ r_cb[:2, :] + r_cb[2, :]
            with np.errstate(divide='ignore', invalid='ignore'):
                lam = -origin[2] / d[:, 2]
                x = origin[0] + lam * d[:, 0]
                y = origin[1] + lam * d[:, 1]
                shape = ((v1 - v0) * s, (u1 - u0) * s)
                width_x = _footprint(x.reshape(shape))
                width_y = _footprint(y.reshape(shape))
                level = truth.board.reflectance(x, y, width_x_m=width_x, width_y_m=width_y)
                level = np.where((lam > 0) & np.isfinite(level), level, np.nan)
            grey = np.where(np.isnan(level), BACKGROUND_LEVEL,
                            BLACK_LEVEL + (WHITE_LEVEL - BLACK_LEVEL) * np.nan_to_num(level))
            image[v0:v1, u0:u1] = grey.reshape(v1 - v0, s, u1 - u0, s).mean(axis=(1, 3))
        if noise_std > 0:
            rng = rng or np.random.default_rng(0)
            image = image + rng.normal(0.0, noise_std, image.shape)
        return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def imu_samples(truth: RigTruth, pose: PoseTruth, rng: np.random.Generator,
                duration_s: float = 1.0, rate_hz: float = 100.0,
                noise_m_s2: float = 0.04, motion_m_s2: float = 0.0) -> Dict[str, np.ndarray]:
    """Specific force samples (m/s^2, IMU frame) of a still pose; ``motion_m_s2`` shakes it."""
    n = max(2, int(round(duration_s * rate_hz)))
    t = np.arange(n) / rate_hz
    f = truth.gravity_m_s2 * pose.specific_force + rng.normal(0.0, noise_m_s2, (n, 3))
    if motion_m_s2 > 0:
        f += motion_m_s2 * np.sin(2 * np.pi * 1.5 * t)[:, None] * np.array([1.0, -0.7, 0.4])
    return {'t': t, 'a': f}


def write_imu_csv(path: str, samples: Dict[str, np.ndarray]) -> None:
    """Write ``t,ax,ay,az`` (s, m/s^2) atomically (the shared recording format)."""
    save_recording(path, samples['t'], samples['a'])


def write_dataset(directory: str, truth: RigTruth, poses: Sequence[PoseTruth],
                  renderer: Optional[Renderer] = None, seed: int = 2,
                  noise_std: float = 1.0, moving: Sequence[int] = ()) -> List[str]:
    """
    Write ``directory/poseNN/<camera>.png`` and ``poseNN/imu.csv``; return the pose names.

    Every camera's image is written, whether or not it sees the board; poses listed in
    ``moving`` get a shaking accelerometer log.
    """
    renderer = renderer or Renderer(truth)
    rng = np.random.default_rng(seed)
    names = []
    for k, pose in enumerate(poses):
        name = f'pose{k:02d}'
        folder = os.path.join(directory, name)
        os.makedirs(folder, exist_ok=True)
        for i, cam in enumerate(truth.names):
            ok, png = cv2.imencode('.png', renderer.render(pose, i, noise_std, rng))
            write_bytes_atomic(os.path.join(folder, f'{cam}.png'), png.tobytes())
        samples = imu_samples(truth, pose, rng, motion_m_s2=2.0 if k in moving else 0.0)
        write_imu_csv(os.path.join(folder, 'imu.csv'), samples)
        names.append(name)
    return names
