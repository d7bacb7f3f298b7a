"""accelcal p2p BAG: camera positions from rendered emitters against the simulated truth."""
from accelcal_ros.camera import CameraModel
from accelcal_ros.cli import main
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, specific_force_from_roll_pitch
from accelcal_ros.p2p.render import pose_from_camera_attitude, render_emitters
from accelcal_ros.recording.sim_bags import bag_path, T0_NS
from accelcal_ros.recording.writer import BagWriter
import numpy as np
import pytest

K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
D = [-0.05, 0.01, 0.0, 0.0, 0.0]
EMITTERS = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])


def _truth(k):
    """Camera position (m) and body roll/pitch/yaw (rad) of frame ``k``."""
    position = np.array([0.5 + 0.05 * k, -6.0, 1.2])
    return position, np.radians(2.0 + 0.5 * k), np.radians(-3.0), np.radians(90.0)


def _write(path, fmt, frames=6):
    camera = CameraModel.from_camera_info(K.reshape(-1), D, 'plumb_bob', 640, 480)
    with BagWriter(path, fmt) as writer:
        writer.add_topic('/camera/image_raw', 'sensor_msgs/Image')
        writer.add_topic('/camera/camera_info', 'sensor_msgs/CameraInfo')
        writer.add_topic('/attitude', 'geometry_msgs/Vector3Stamped')
        writer.add_topic('/imu/data_raw', 'sensor_msgs/Imu')
        for k in range(frames):
            ns = T0_NS + k * 200_000_000
            position, roll, pitch, yaw = _truth(k)
            rotation, translation = pose_from_camera_attitude(roll, pitch, yaw, position,
                                                              DEFAULT_IMU_TO_CAMERA)
            image, _, _ = render_emitters(EMITTERS, rotation, translation, camera, seed=k)
            for j in range(-5, 5):   # IMU at 50 Hz, roll turning steadily (0.5 deg/frame)
                t_imu = ns + j * 20_000_000
                roll_imu = roll + np.radians(0.5) * j / 10.0
                force = specific_force_from_roll_pitch(roll_imu, pitch) * 9.80665
                writer.write('/imu/data_raw', t_imu, writer.imu_message(t_imu, force, 'imu'))
            writer.write('/attitude', ns, writer.vector3_stamped_message(ns, (roll, pitch, 0.0),
                                                                         'imu'))
            writer.write('/camera/camera_info', ns, writer.camera_info_message(
                ns, K, D, 640, 480, 'camera_optical'))
            writer.write('/camera/image_raw', ns, writer.image_message(ns, image,
                                                                       'camera_optical'))
    return path


@pytest.mark.parametrize('fmt,source', [('mcap', '--attitude'), ('ros1', '--imu')])
def test_p2p_from_bag_matches_truth(tmp_path, fmt, source):
    """Every frame is solved; positions within 2 cm and yaw within 0.2 deg of the truth."""
    bag = _write(bag_path(tmp_path, 'p2p', fmt), fmt)
    out = tmp_path / 'poses.csv'
    topic = '/attitude' if source == '--attitude' else '/imu/data_raw'
    assert main(['p2p', str(bag), '--image', '/camera/image_raw', '--camera-info',
                 '/camera/camera_info', source, topic, '-o', str(out)]) == 0
    rows = np.genfromtxt(out, delimiter=',', skip_header=1, usecols=range(8))
    assert rows.shape[0] == 6
    for k, row in enumerate(rows):
        position, _, _, yaw = _truth(k)
        assert row[0] == pytest.approx((T0_NS + k * 200_000_000) / 1e9, abs=1e-6)
        np.testing.assert_allclose(row[1:4], position, atol=0.02)
        assert abs(row[4] - np.degrees(yaw)) < 0.2


def test_p2p_bag_needs_an_attitude_source(tmp_path, capsys):
    """Without --attitude/--imu and with both topics present, the error names them."""
    bag = _write(bag_path(tmp_path, 'p2p', 'sqlite3'), 'sqlite3', frames=1)
    assert main(['p2p', str(bag), '--imu', '/nope', '-o', str(tmp_path / 'x.csv')]) != 0
    assert 'no topic /nope' in capsys.readouterr().err
    assert not (tmp_path / 'x.csv').exists()
