"""
Camera journeys: the rig calibration bag (9x6 board) and the drive the panorama is made of.

Both use one known rig (:func:`accelcal_ros.rig.render.default_truth` at 400x300: three
cameras 45 deg apart, own K and D, ~1 deg mount errors, a known ``imu_to_camera``), so the
rig file ``accelcal rig-calibrate rosbag2_rig`` writes is the one the drive was made with.
"""
import math
import os
from typing import Any, List, Sequence, Tuple

from accelcal_ros.camera.rig import Rig, RigCamera
from accelcal_ros.fileio import write_bytes_atomic
from accelcal_ros.frames import specific_force_from_roll_pitch
from accelcal_ros.lidar import scanner_sim
from accelcal_ros.panorama import render as scene_render
from accelcal_ros.recording.sim_bags import T0_NS
from accelcal_ros.recording.writer import BagWriter, sensor_data_qos
from accelcal_ros.rig.board import Board
from accelcal_ros.rig.render import default_truth, imu_samples, plan_poses, Renderer, RigTruth
from accelcal_ros.sample_data.imu import raw_m_s2
from accelcal_ros.sample_data.lidar import BORESIGHT_TRUTH, LEVER_ARM_M
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
import cv2
import numpy as np

WIDTH, HEIGHT, FOCAL_PX = 400, 300, 212.0
BOARD = Board(9, 6, 0.025)
POSES = 15
IMU_RATE_HZ = 100.0
MOVE_S, STILL_S = 1.0, 2.0
DRIVE_FRAMES, FRAME_PERIOD_S = 10, 0.1


def rig_truth() -> RigTruth:
    """Return the sample rig (the truth both camera recordings are rendered with)."""
    return default_truth(width=WIDTH, height=HEIGHT, focal_px=FOCAL_PX, board=BOARD)


def truth_as_rig(truth: RigTruth) -> Rig:
    """Return the truth as the stitcher's :class:`Rig` (``R_0i``, ``imu_to_camera``)."""
    cameras = [RigCamera(name, w, h, k, d.tolist(), r) for name, (w, h), k, d, r
               in zip(truth.names, truth.sizes, truth.K, truth.D, truth.R)]
    return Rig(tuple(cameras), truth.imu_to_camera)


def _swing(f_from: np.ndarray, f_to: np.ndarray, rng: np.random.Generator) -> Tuple[Any, Any]:
    """Specific force (m/s^2) and rate (rad/s) while the rig is carried to the next pose."""
    n = int(MOVE_S * IMU_RATE_HZ)
    s = (np.arange(n) + 0.5) / n
    envelope = np.sin(np.pi * s)[:, None]
    f = (1 - s)[:, None] * f_from + s[:, None] * f_to
    f = f + 3.0 * envelope * np.sin(2 * np.pi * 3.0 * s)[:, None] * np.array([1.0, -0.6, 0.3])
    gyro = 0.8 * envelope * np.array([0.2, -0.5, 1.0]) + rng.normal(0, 0.002, (n, 3))
    return f, gyro


def write_rig_bag(directory: str) -> None:
    """``rosbag2_rig``: 15 still poses of the board (3 frame sets each), the IMU between."""
    truth = rig_truth()
    rng = np.random.default_rng(4)
    renderer = Renderer(truth)
    events: List[Tuple[float, str, Any]] = []
    t = 0.0
    previous = truth.gravity_m_s2 * np.array([0.0, 0.0, 1.0])
    for pose in plan_poses(truth, POSES):
        images = [renderer.render(pose, i, 1.0, rng) for i in range(len(truth.names))]
        still = imu_samples(truth, pose, rng, duration_s=STILL_S, rate_hz=IMU_RATE_HZ,
                            noise_m_s2=0.01)
        f_move, g_move = _swing(previous, still['a'][0], rng)
        previous = still['a'][-1]
        events += [(t + j / IMU_RATE_HZ, 'imu', (f_move[j], g_move[j]))
                   for j in range(len(f_move))]
        t += MOVE_S
        gyro_still = rng.normal(0.0, 0.001, (len(still['t']), 3))
        events += [(t + ts, 'imu', (still['a'][j], gyro_still[j]))
                   for j, ts in enumerate(still['t'])]
        for offset in (0.35, 0.5 * STILL_S, STILL_S - 0.35):
            events.append((t + offset, 'set', images))
        t += STILL_S
    _write_camera_bag(os.path.join(directory, 'rosbag2_rig'), truth.names, events, ())


def _write_camera_bag(path: str, names: Sequence[str], events: List[Tuple[float, str, Any]],
                      lidar: Sequence[Tuple[float, str, Any]]) -> None:
    """Write IMU samples and frame sets (cameras triggered together, received 3 ms apart)."""
    with BagWriter(path, 'mcap') as writer:
        writer.add_topic('/imu/data_raw', 'sensor_msgs/Imu', [sensor_data_qos()])
        for name in names:
            writer.add_topic(f'/{name}/image_raw', 'sensor_msgs/Image')
        if lidar:
            writer.add_topic('/velodyne_points', 'sensor_msgs/PointCloud2',
                             [sensor_data_qos()])
            writer.add_topic('/odometry/filtered', 'nav_msgs/Odometry')
        for ts, kind, payload in sorted(list(events) + list(lidar), key=lambda e: e[0]):
            ns = T0_NS + int(round(ts * 1e9))
            if kind == 'imu':
                writer.write('/imu/data_raw', ns, writer.imu_message(
                    ns, raw_m_s2(payload[0]), 'imu_link', payload[1]))
            elif kind == 'set':
                for i, (name, image) in enumerate(zip(names, payload)):
                    writer.write(f'/{name}/image_raw', ns + (i + 1) * 3_000_000,
                                 writer.image_message(ns, image, f'{name}_optical_frame'))
            elif kind == 'scan':
                writer.write('/velodyne_points', ns,
                             writer.pointcloud2_message(ns, payload, 'lidar_link'))
            else:  # odometry: (position, quaternion)
                writer.write('/odometry/filtered', ns, writer.odometry_message(
                    ns, payload[0], payload[1], 'map', 'base_link'))


def drive_attitude(t_s: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Roll and pitch (rad) of the rig during the drive: a slow 2-6 deg sway."""
    return (np.radians(3.0) * np.sin(2 * math.pi * 0.4 * t_s),
            np.radians(2.0) + np.radians(4.0) * np.sin(2 * math.pi * 0.25 * t_s))


def write_drive(directory: str) -> None:
    """``rosbag2_drive`` (cameras, IMU, scans, odometry); ``img0..2.png`` (pitch 15 deg)."""
    truth = rig_truth()
    rig = truth_as_rig(truth)
    rng = np.random.default_rng(7)
    scene = scene_render.make_scene(1800, 900, seed=5)
    duration = DRIVE_FRAMES * FRAME_PERIOD_S
    t_imu = np.arange(int(round((duration + 0.5) * IMU_RATE_HZ))) / IMU_RATE_HZ
    roll, pitch = drive_attitude(t_imu)
    force = specific_force_from_roll_pitch(roll, pitch) * STANDARD_GRAVITY_M_S2
    force = force + rng.normal(0.0, 0.02, force.shape)
    events: List[Tuple[float, str, Any]] = [(float(t), 'imu', (f, np.zeros(3)))
                                            for t, f in zip(t_imu, force)]
    for k in range(DRIVE_FRAMES):
        t = 0.25 + k * FRAME_PERIOD_S
        r, p = drive_attitude(np.array([t]))
        views = scene_render.render_camera_views(scene, rig, float(r[0]), float(p[0]),
                                                 truth.imu_to_camera)
        views = [np.clip(v + rng.normal(0, 1.5, v.shape), 0, 255).astype(np.uint8)
                 for v in views]
        events.append((t, 'set', views))
    moving = scanner_sim.simulate_moving_platform(
        duration_s=0.2, seed=3, boresight=BORESIGHT_TRUTH, lever_arm_m=LEVER_ARM_M,
        scan_start_s=0.3)
    lidar: List[Tuple[float, str, Any]] = [(moving.scan_start_s, 'scan', moving.cloud)]
    lidar += [(float(t), 'odom', (p, q)) for t, p, q in zip(
        moving.poses.t, moving.poses.position, moving.poses.quat_xyzw)]
    _write_camera_bag(os.path.join(directory, 'rosbag2_drive'), truth.names, events, lidar)
    still = scene_render.render_camera_views(scene, rig, 0.0, math.radians(15.0),
                                             truth.imu_to_camera)
    for i, view in enumerate(still):
        ok, png = cv2.imencode('.png', view)
        write_bytes_atomic(os.path.join(directory, f'img{i}.png'), png.tobytes())
