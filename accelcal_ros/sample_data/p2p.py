"""P2P journey: one camera sees two emitters 1 m apart while the platform moves and tilts."""
import os
from typing import Tuple

from accelcal_ros.camera import CameraModel
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, specific_force_from_roll_pitch
from accelcal_ros.p2p.render import pose_from_camera_attitude, render_emitters
from accelcal_ros.recording.sim_bags import T0_NS
from accelcal_ros.recording.writer import BagWriter, sensor_data_qos
from accelcal_ros.sample_data.imu import raw_m_s2
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
import numpy as np

K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
D = [-0.05, 0.01, 0.0, 0.0, 0.0]
EMITTERS = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
FRAMES, PERIOD_NS = 20, 100_000_000


def truth(k: int) -> Tuple[np.ndarray, float, float, float]:
    """Camera position (m, object frame) and body roll, pitch, yaw (rad) of frame ``k``."""
    position = np.array([0.5 + 0.02 * k, -6.0, 1.2])
    return position, np.radians(2.0 + 0.2 * k), np.radians(-3.0), np.radians(90.0)


def write(directory: str) -> None:
    """Write ``rosbag2_p2p``: image + camera_info at 10 Hz, ``/imu/data_raw`` at 50 Hz."""
    camera = CameraModel.from_camera_info(K.reshape(-1).tolist(), D, 'plumb_bob', 640, 480)
    with BagWriter(os.path.join(directory, 'rosbag2_p2p'), 'mcap') as writer:
        writer.add_topic('/camera/image_raw', 'sensor_msgs/Image')
        writer.add_topic('/camera/camera_info', 'sensor_msgs/CameraInfo')
        writer.add_topic('/imu/data_raw', 'sensor_msgs/Imu', [sensor_data_qos()])
        for k in range(FRAMES):
            ns = T0_NS + k * PERIOD_NS
            position, roll, pitch, yaw = truth(k)
            rotation, translation = pose_from_camera_attitude(roll, pitch, yaw, position.tolist(),
                                                              DEFAULT_IMU_TO_CAMERA)
            image, _, _ = render_emitters(EMITTERS, rotation, translation, camera, seed=k)
            force = raw_m_s2(specific_force_from_roll_pitch(roll, pitch)
                             * STANDARD_GRAVITY_M_S2)
            for j in range(5):
                t_imu = ns - 40_000_000 + j * 20_000_000
                writer.write('/imu/data_raw', t_imu,
                             writer.imu_message(t_imu, force, 'imu_link'))
            writer.write('/camera/camera_info', ns, writer.camera_info_message(
                ns, K, D, 640, 480, 'camera_optical_frame'))
            writer.write('/camera/image_raw', ns, writer.image_message(
                ns, image, 'camera_optical_frame'))
