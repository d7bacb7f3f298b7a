r"""
Simulated VLP-16 scanner, IMU and rig: paper B's calibration protocol and a moving platform.

Scanner (Velodyne VLP-16 datasheet): 16 lasers at elevations -15..+15 deg in 2 deg steps
(``ring`` 0 = lowest), 0.2 deg azimuth steps at 10 Hz (1800 firings per revolution,
55.296 us apart, lasers 2.304 us apart within a firing), range noise 3 cm (1 sigma, along
the beam), 100 m maximum range. Scanner frame: x forward, y left, z up (the spin axis),
azimuth measured from x towards y. Every point carries its firing time.

Scene: an axis-aligned room (floor ``z = 0``, four walls, ceiling) with optional solid
boxes (furniture, pillars); rays are intersected exactly (slab method).

Rig: ``boresight`` maps LiDAR vectors into the IMU frame (``v_imu = R v_lidar``),
``lever_arm_m`` is the LiDAR origin in the IMU frame. The IMU reads the specific force
``f = C^T [0, 0, g]`` (REP-145) distorted by an optional
:class:`~accelcal_ros.sensor.model.SensorModel` (in g) plus white noise, and the
gyro angular rate plus noise.

Paper B's protocol: 15 static positions, the scanner tilted about its X axis by
-90..+90 deg in 45 deg steps and about its Y axis by -90, 0, +90 deg
(:func:`paper_protocol_tilts_deg`); at each the IMU logs a still period (preceded by a
second of handling motion) and the scanner records one or more revolutions.
"""
from dataclasses import dataclass, field
from typing import Any, List, Optional, Sequence, Tuple

from accelcal_ros.frames import rot_x, rot_y, rotation_from_rpy_radians
from accelcal_ros.lidar.cloud import make_cloud
from accelcal_ros.lidar.imu_log import ImuLog
from accelcal_ros.lidar.poses import PoseStream
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

VLP16_ELEVATIONS_DEG = np.arange(-15.0, 16.0, 2.0)
FIRING_PERIOD_S = 55.296e-6
LASER_PERIOD_S = 2.304e-6


@dataclass
class Room:
    """Axis-aligned room ``[x0, x1] x [y0, y1] x [0, height]`` (m) with solid boxes."""

    x_range: tuple = (-4.0, 6.0)
    y_range: tuple = (-3.5, 4.5)
    height: float = 3.0
    boxes: List[tuple] = field(default_factory=lambda: [((2.0, 1.5, 0.0), (3.2, 2.3, 0.75))])

    def cast(self, origins: ArrayLike, directions: ArrayLike) -> np.ndarray:
        """Return the range (m) of each ray to the first surface (inf if none)."""
        o = np.asarray(origins, dtype=float)
        d = np.asarray(directions, dtype=float)
        lo = np.array([self.x_range[0], self.y_range[0], 0.0])
        hi = np.array([self.x_range[1], self.y_range[1], self.height])
        with np.errstate(divide='ignore', invalid='ignore'):
            bound = np.where(d > 0, hi, lo)
            t_axis = np.where(d != 0, (bound - o) / d, np.inf)
            t = np.min(np.where(t_axis > 0, t_axis, np.inf), axis=1)
            for bmin, bmax in self.boxes:
                t1 = (np.asarray(bmin) - o) / d
                t2 = (np.asarray(bmax) - o) / d
                near = np.nanmax(np.minimum(t1, t2), axis=1)
                far = np.nanmin(np.maximum(t1, t2), axis=1)
                hit = (near <= far) & (near > 0)
                t = np.where(hit & (near < t), near, t)
        return t

    def surface_distance(self, points: ArrayLike) -> np.ndarray:
        """Return each point's distance (m) to the nearest surface of the scene."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        lo = np.array([self.x_range[0], self.y_range[0], 0.0])
        hi = np.array([self.x_range[1], self.y_range[1], self.height])
        best = np.min(np.abs(np.hstack([p - lo, hi - p])), axis=1)
        for bmin, bmax in self.boxes:
            bmin, bmax = np.asarray(bmin, float), np.asarray(bmax, float)
            outside = np.linalg.norm(np.maximum(np.maximum(bmin - p, p - bmax), 0.0), axis=1)
            inside = np.min(np.abs(np.hstack([p - bmin, bmax - p])), axis=1)
            is_in = np.all((p >= bmin) & (p <= bmax), axis=1)
            best = np.minimum(best, np.where(is_in, inside, outside))
        return best


@dataclass
class Vlp16:
    """VLP-16 geometry and noise; ``revolutions`` per scan at ``rate_hz``."""

    azimuth_step_deg: float = 0.2
    rate_hz: float = 10.0
    range_noise_m: float = 0.03
    max_range_m: float = 100.0
    min_range_m: float = 0.5

    def beams(self, revolutions: int = 1) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return unit directions (M, 3), ring (M,), time offsets (M,) s, scanner frame."""
        per_rev = int(round(360.0 / self.azimuth_step_deg))
        firings = per_rev * revolutions
        period = 1.0 / self.rate_hz / per_rev
        az = np.radians(np.arange(firings) * self.azimuth_step_deg)
        el = np.radians(VLP16_ELEVATIONS_DEG)
        az_g, el_g = np.meshgrid(az, el, indexing='ij')
        dirs = np.stack([np.cos(el_g) * np.cos(az_g), np.cos(el_g) * np.sin(az_g),
                         np.sin(el_g)], axis=-1).reshape(-1, 3)
        ring = np.tile(np.arange(16), firings)
        times = (np.arange(firings)[:, None] * period
                 + np.arange(16)[None, :] * LASER_PERIOD_S).reshape(-1)
        return dirs, ring, times

    def measure(self, true_range: np.ndarray,
                rng: np.random.Generator) -> Tuple[np.ndarray, np.ndarray]:
        """Return noisy ranges and the mask of valid returns."""
        valid = np.isfinite(true_range) & (true_range >= self.min_range_m) \
            & (true_range <= self.max_range_m)
        noisy = true_range + rng.normal(0.0, self.range_noise_m, true_range.shape)
        return noisy, valid


def scan_static(room: Room, scanner: 'Vlp16', rotation_world_lidar: ArrayLike,
                origin_world: ArrayLike, revolutions: int = 1,
                rng: Optional[np.random.Generator] = None,
                t0: float = 0.0) -> Tuple[np.ndarray, np.ndarray]:
    """
    One static scan; returns ``(cloud, truth_world)``.

    ``cloud`` (structured: x y z in the LiDAR frame, intensity, ring, time relative to
    ``t0``) and the noiseless hit points in the world frame.
    """
    rng = rng or np.random.default_rng(0)
    dirs, ring, times = scanner.beams(revolutions)
    world_dirs = dirs @ np.asarray(rotation_world_lidar).T
    origins = np.broadcast_to(np.asarray(origin_world, dtype=float), world_dirs.shape)
    true_range = room.cast(origins, world_dirs)
    noisy, valid = scanner.measure(true_range, rng)
    pts = dirs[valid] * noisy[valid, None]
    truth = origins[valid] + world_dirs[valid] * true_range[valid, None]
    intensity = np.clip(100.0 / np.maximum(true_range[valid], 0.5), 0, 255)
    return make_cloud(pts, intensity, ring[valid], times[valid]), truth


def paper_protocol_tilts_deg() -> List[Tuple[float, float]]:
    """Return paper B's 15 (tilt about X, tilt about Y) pairs in degrees."""
    return [(a, b) for b in (-90.0, 0.0, 90.0) for a in (-90.0, -45.0, 0.0, 45.0, 90.0)]


@dataclass
class ProtocolPosition:
    """One simulated static position: cloud, IMU log and the truth."""

    name: str
    cloud: np.ndarray
    imu: ImuLog
    rotation_world_lidar: np.ndarray
    gravity_true_imu: np.ndarray


def simulate_imu_static(rotation_world_imu: ArrayLike, duration_s: float, rate_hz: float,
                        rng: np.random.Generator, model: Any = None,
                        accel_noise_m_s2: float = 0.02, gyro_noise_rad_s: float = 0.002,
                        handling_s: float = 1.0, t0: float = 0.0) -> Tuple[ImuLog, np.ndarray]:
    """IMU log: ``handling_s`` of motion, then ``duration_s`` still (specific force, m/s^2)."""
    n_move = int(round(handling_s * rate_hz))
    n_still = int(round(duration_s * rate_hz))
    n = n_move + n_still
    t = t0 + np.arange(n) / rate_hz
    f_true = np.asarray(rotation_world_imu).T @ np.array([0.0, 0.0, STANDARD_GRAVITY_M_S2])
    accel = np.repeat(f_true[None, :], n, axis=0)
    gyro = np.zeros((n, 3))
    if n_move:
        phase = np.arange(n_move) / rate_hz
        wobble = np.sin(2 * np.pi * 1.5 * phase)[:, None] * np.array([0.4, -0.3, 0.2])
        gyro[:n_move] = wobble
        accel[:n_move] += 0.8 * np.cos(2 * np.pi * 2.0 * phase)[:, None] * np.array(
            [0.5, 0.3, -0.4])
    if model is not None:
        accel = model.distort(accel / STANDARD_GRAVITY_M_S2) * STANDARD_GRAVITY_M_S2
    accel = accel + rng.normal(0.0, accel_noise_m_s2, accel.shape)
    gyro = gyro + rng.normal(0.0, gyro_noise_rad_s, gyro.shape)
    return ImuLog(t, accel, gyro), f_true


def box_room(size_m: Sequence[float] = (8.0, 8.0, 8.0),
             corner_m: Sequence[float] = (-4.0, -4.0)) -> Room:
    """
    Return an empty box-shaped room (m): ceiling and walls as large as the floor.

    In such a room, plane assignments other than the floor fit the boresight as well
    (:mod:`accelcal_ros.lidar.floor_assign`).
    """
    sx, sy, sz = (float(v) for v in size_m)
    x0, y0 = (float(v) for v in corner_m)
    return Room((x0, x0 + sx), (y0, y0 + sy), sz, [])


def tilt_rotation(a_deg: float, b_deg: float, order: str = 'xy') -> np.ndarray:
    """
    Return the scanner's orientation (LiDAR -> world) at tilt ``(a, b)`` deg.

    ``order='xy'``: ``Rx(a) Ry(b)`` (tilt about X composed first, paper B as simulated so
    far); ``'yx'``: ``Ry(b) Rx(a)``.
    """
    rx, ry = rot_x(np.radians(a_deg)), rot_y(np.radians(b_deg))
    if order == 'xy':
        return rx @ ry
    if order == 'yx':
        return ry @ rx
    raise ValueError(f"order must be 'xy' or 'yx', got {order!r}")


def simulate_protocol(boresight: ArrayLike,
                      tilts_deg: Optional[Sequence[Tuple[float, float]]] = None,
                      room: Optional[Room] = None, scanner: Optional['Vlp16'] = None,
                      seed: int = 0, scanner_origin: Sequence[float] = (0.0, 0.0, 1.2),
                      imu_model: Any = None, still_s: float = 10.0, imu_rate_hz: float = 200.0,
                      revolutions: int = 1, order: str = 'xy') -> List['ProtocolPosition']:
    """
    Simulate paper B's static protocol; returns a list of :class:`ProtocolPosition`.

    At tilt ``(a, b)`` the scanner's orientation is :func:`tilt_rotation` (``Rx(a) Ry(b)``
    for ``order='xy'``, LiDAR -> world) about its own origin at ``scanner_origin``; the
    IMU's is that times ``R^T``.
    """
    room = room or Room()
    scanner = scanner or Vlp16()
    rng = np.random.default_rng(seed)
    boresight = np.asarray(boresight, dtype=float)
    out = []
    for k, (a, b) in enumerate(tilts_deg or paper_protocol_tilts_deg()):
        r_wl = tilt_rotation(a, b, order)
        cloud, _ = scan_static(room, scanner, r_wl, scanner_origin, revolutions, rng)
        imu, f_true = simulate_imu_static(r_wl @ boresight.T, still_s, imu_rate_hz, rng,
                                          imu_model)
        out.append(ProtocolPosition(f'pos{k + 1:02d}', cloud, imu, r_wl, f_true))
    return out


@dataclass
class Trajectory:
    """Smooth body (IMU) trajectory in the navigation frame, vectorised in time."""

    start_m: tuple = (-12.0, -6.0, 1.8)
    velocity_m_s: tuple = (2.5, 1.0, 0.0)
    sway_m: float = 0.6
    sway_hz: float = 0.3
    yaw0_rad: float = 0.3
    yaw_rate_rad_s: float = 0.35
    roll_amp_rad: float = 0.05
    pitch_amp_rad: float = 0.04
    wobble_hz: float = 0.7

    def pose(self, t: ArrayLike) -> Tuple[np.ndarray, np.ndarray]:
        """Return ``(C (N, 3, 3) body -> nav, p (N, 3))`` at times ``t`` (s)."""
        t = np.asarray(t, dtype=float).reshape(-1)
        p = np.asarray(self.start_m) + t[:, None] * np.asarray(self.velocity_m_s)
        p[:, 1] += self.sway_m * np.sin(2 * np.pi * self.sway_hz * t)
        p[:, 2] += 0.1 * np.sin(2 * np.pi * 0.5 * t)
        yaw = self.yaw0_rad + self.yaw_rate_rad_s * t
        roll = self.roll_amp_rad * np.sin(2 * np.pi * self.wobble_hz * t)
        pitch = self.pitch_amp_rad * np.cos(2 * np.pi * 1.3 * self.wobble_hz * t)
        c = Rotation.from_euler('xyz', np.stack([roll, pitch, yaw], axis=1)).as_matrix()
        return c, p

    def pose_stream(self, t0: float, t1: float, rate_hz: float = 200.0) -> PoseStream:
        """Return the :class:`PoseStream` sampled at ``rate_hz`` over ``[t0, t1]``."""
        t = np.arange(t0, t1 + 0.5 / rate_hz, 1.0 / rate_hz)
        c, p = self.pose(t)
        return PoseStream(t, p, Rotation.from_matrix(c).as_quat())


@dataclass
class MovingScene:
    """A moving-platform scan with its truth (see :func:`simulate_moving_platform`)."""

    cloud: np.ndarray
    scan_start_s: float
    poses: PoseStream
    truth_world: np.ndarray
    boresight: np.ndarray
    lever_arm_m: np.ndarray
    trajectory: Trajectory
    room: Room


def big_hall() -> Room:
    """Return a 60 x 40 x 8 m hall with pillars (the moving-platform scene)."""
    boxes = [((x, y, 0.0), (x + 0.6, y + 0.6, 8.0)) for x in (-10.0, 0.0, 10.0)
             for y in (-8.0, 8.0)]
    boxes.append(((4.0, -2.0, 0.0), (7.0, 1.0, 1.5)))
    return Room((-30.0, 30.0), (-20.0, 20.0), 8.0, boxes)


def simulate_moving_platform(duration_s: float = 1.0, seed: int = 0,
                             boresight: Optional[ArrayLike] = None,
                             lever_arm_m: Sequence[float] = (0.3, -0.1, 0.25),
                             pose_rate_hz: float = 200.0, scan_start_s: float = 100.0,
                             range_noise_m: float = 0.03,
                             trajectory: Optional['Trajectory'] = None,
                             room: Optional[Room] = None,
                             pose_margin_s: float = 0.05) -> 'MovingScene':
    """
    Simulate a scanner on a moving platform; the truth is the noiseless world points.

    Each point is cast from the LiDAR pose at its own firing time (exact motion); the
    pose stream (body poses at ``pose_rate_hz``) covers the scan plus ``pose_margin_s``
    (negative: the stream is shorter than the scan, to exercise dropping).
    """
    rng = np.random.default_rng(seed)
    room = room or big_hall()
    trajectory = trajectory or Trajectory()
    boresight = (rotation_from_rpy_radians(*np.radians([1.0, -0.5, 2.0])) @ rot_y(
        np.radians(-30.0)) if boresight is None else np.asarray(boresight, dtype=float))
    lever = np.asarray(lever_arm_m, dtype=float)
    scanner = Vlp16(range_noise_m=range_noise_m)
    revolutions = max(1, int(round(duration_s * scanner.rate_hz)))
    dirs, ring, times = scanner.beams(revolutions)
    abs_t = scan_start_s + times
    c_b, p_b = trajectory.pose(abs_t - scan_start_s)
    c_l = c_b @ boresight
    origins = p_b + np.einsum('nij,j->ni', c_b, lever)
    world_dirs = np.einsum('nij,nj->ni', c_l, dirs)
    true_range = room.cast(origins, world_dirs)
    noisy, valid = scanner.measure(true_range, rng)
    pts = dirs[valid] * noisy[valid, None]
    truth = origins[valid] + world_dirs[valid] * true_range[valid, None]
    cloud = make_cloud(pts, np.clip(100.0 / true_range[valid], 0, 255), ring[valid],
                       times[valid])
    t_end = times[-1]
    poses = trajectory.pose_stream(-pose_margin_s, t_end + pose_margin_s, pose_rate_hz)
    poses = PoseStream(poses.t + scan_start_s, poses.position, poses.quat_xyzw)
    return MovingScene(cloud, scan_start_s, poses, truth, boresight, lever, trajectory, room)


def default_boresight() -> np.ndarray:
    """Return the simulated rig's true boresight: a few degrees off a 45 deg mount."""
    return rotation_from_rpy_radians(*np.radians([1.2, -2.1, 3.4])) @ rot_y(np.radians(45.0))


def nominal_mount() -> np.ndarray:
    """Return the nominal mounting (the prior): the LiDAR pitched 45 deg (paper B Fig. 2)."""
    return rot_y(np.radians(45.0))


def positions_for_calibration(protocol: Sequence['ProtocolPosition'],
                              model: Any = None) -> List[Any]:
    """Turn simulated positions into boresight inputs (static segment + gravity)."""
    from accelcal_ros.lidar.boresight import StaticPosition
    from accelcal_ros.lidar.cloud import xyz
    from accelcal_ros.lidar.static_segments import longest_static_segment

    out = []
    for pos in protocol:
        seg = longest_static_segment(pos.imu.t, pos.imu.accel, pos.imu.gyro, model)
        gravity = seg.gravity_m_s2 if seg is not None else np.full(3, np.nan)
        std = seg.direction_std_rad() if seg is not None else 0.0
        out.append(StaticPosition(pos.name, xyz(pos.cloud), gravity, std,
                                  calibrated=model is not None))
    return out


def write_protocol(directory: Any, protocol: Sequence['ProtocolPosition'],
                   data: str = 'binary_compressed') -> None:
    """Write simulated positions as ``posNN.pcd`` + ``posNN_imu.csv`` (the CLI's input)."""
    import os

    from accelcal_ros.lidar.imu_log import write_imu_csv
    from accelcal_ros.lidar.pcd import write_pcd

    os.makedirs(directory, exist_ok=True)
    for pos in protocol:
        write_pcd(os.path.join(directory, f'{pos.name}.pcd'), pos.cloud, data)
        write_imu_csv(os.path.join(directory, f'{pos.name}_imu.csv'), pos.imu)
