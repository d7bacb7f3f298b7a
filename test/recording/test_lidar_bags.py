"""boresight BAG and georeference BAG against the directory / PCD+CSV paths and the truth."""
from accelcal_ros.cli import main
from accelcal_ros.fileio import write_text_atomic
from accelcal_ros.lidar import scanner_sim as sim
from accelcal_ros.lidar.boresight import load_boresight
from accelcal_ros.lidar.cloud import read_cloud, xyz
from accelcal_ros.lidar.imu_log import ImuLog
from accelcal_ros.lidar.pcd import write_pcd
from accelcal_ros.lidar.poses import write_poses_csv
from accelcal_ros.lidar.wahba import rotation_angle_deg
from accelcal_ros.recording.sim_bags import bag_path, FORMATS, write_protocol_bag
from accelcal_ros.recording.writer import BagWriter
from accelcal_ros.textformats import dump_yaml, load_yaml_mapping
import numpy as np
import pytest

TRUTH = sim.default_boresight()


@pytest.fixture(scope='module')
def protocol(tmp_path_factory):
    """Simulate 15 positions of paper B (3 s still); write the directory, its boresight."""
    root = tmp_path_factory.mktemp('bs')
    positions = sim.simulate_protocol(TRUTH, seed=5, still_s=3.0)
    sim.write_protocol(root / 'dir', positions, 'binary')
    out = root / 'dir.yaml'
    assert main(['boresight', str(root / 'dir'), '-o', str(out), '--prior-rpy-deg', '0', '45',
                 '0']) == 0
    return {'root': root, 'positions': positions, 'dir_yaml': out}


@pytest.mark.parametrize('fmt', FORMATS)
def test_boresight_from_bag_equals_directory(protocol, fmt, tmp_path, capsys):
    """One continuous recording gives the directory's positions, figures and report."""
    bag = write_protocol_bag(bag_path(tmp_path, 'rec', fmt), fmt, protocol['positions'],
                             scans_per_position=1)
    out = tmp_path / 'bag.yaml'
    capsys.readouterr()
    assert main(['boresight', str(bag), '--points', '/velodyne_points', '--imu', 'imu/data',
                 '-o', str(out), '--prior-rpy-deg', '0', '45', '0']) == 0
    text = capsys.readouterr().out
    assert 'pos15: still' in text and 'hold-out' in text
    from_bag, from_dir = load_yaml_mapping(out), load_yaml_mapping(protocol['dir_yaml'])
    assert from_bag['positions'] == from_dir['positions']
    assert rotation_angle_deg(load_boresight(out), TRUTH) < 0.05
    # same scans, same IMU samples; a continuous recording's still periods end ~0.25 s
    # earlier (the next position's motion enters the stillness window), hence the tolerance
    assert rotation_angle_deg(load_boresight(out), load_boresight(protocol['dir_yaml'])) < 0.003
    np.testing.assert_allclose(from_bag['per_position_error_deg'],
                               from_dir['per_position_error_deg'], atol=0.01)
    np.testing.assert_allclose(from_bag['floor_normals_lidar'], from_dir['floor_normals_lidar'],
                               atol=2e-4)
    np.testing.assert_allclose(from_bag['gravity_imu_m_s2'], from_dir['gravity_imu_m_s2'],
                               atol=2e-3)


def test_boresight_bag_accelerometer_only(protocol, tmp_path, capsys):
    """Without gyro (covariance -1) the accelerometer finds the still periods."""
    positions = [sim.ProtocolPosition(p.name, p.cloud, ImuLog(p.imu.t, p.imu.accel, None),
                                      p.rotation_world_lidar, p.gravity_true_imu)
                 for p in protocol['positions']]
    bag = bag_path(tmp_path, 'acc', 'mcap')
    write_protocol_bag(bag, 'mcap', positions, scans_per_position=3)
    out = tmp_path / 'acc.yaml'
    assert main(['boresight', str(bag), '-o', str(out), '--clouds-per-position', '2']) == 0
    captured = capsys.readouterr()
    assert 'from the accelerometer' in captured.err and '2 scan(s)' in captured.out
    assert rotation_angle_deg(load_boresight(out), TRUTH) < 0.05


def test_georeference_from_bag_equals_files(tmp_path):
    """Scans and Odometry in a bag give the points of --cloud/--poses (and the truth)."""
    scene = sim.simulate_moving_platform(duration_s=0.2, seed=1)
    write_pcd(tmp_path / 'scan.pcd', scene.cloud, 'binary')
    write_poses_csv(tmp_path / 'poses.csv', scene.poses)
    write_text_atomic(tmp_path / 'bs.yaml',
                      dump_yaml({'R': [float(v) for v in scene.boresight.reshape(-1)]}))
    bag = tmp_path / 'geo.bag'
    with BagWriter(bag) as writer:
        writer.add_topic('/odom', 'nav_msgs/Odometry')
        writer.add_topic('/points', 'sensor_msgs/PointCloud2')
        events = [(t, k) for k, t in enumerate(scene.poses.t)] + [(scene.scan_start_s, -1)]
        for t, k in sorted(events):
            ns = int(round(t * 1e9))
            if k < 0:
                writer.write('/points', ns, writer.pointcloud2_message(ns, scene.cloud, 'lidar'))
            else:
                writer.write('/odom', ns, writer.odometry_message(
                    ns, scene.poses.position[k], scene.poses.quat_xyzw[k], 'map', 'imu_link'))
    lever = ['--lever-arm'] + [str(v) for v in scene.lever_arm_m]
    common = ['--boresight', str(tmp_path / 'bs.yaml')] + lever
    assert main(['georeference', '--cloud', str(tmp_path / 'scan.pcd'), '--poses',
                 str(tmp_path / 'poses.csv'), '--time-base', str(scene.scan_start_s),
                 '-o', str(tmp_path / 'files.ply')] + common) == 0
    assert main(['georeference', str(bag), '-o', str(tmp_path / 'bag.ply')] + common) == 0
    from_files = xyz(read_cloud(tmp_path / 'files.ply'))
    from_bag = xyz(read_cloud(tmp_path / 'bag.ply'))
    assert from_bag.shape == from_files.shape
    np.testing.assert_allclose(from_bag, from_files, atol=1e-6)
    err = np.linalg.norm(from_bag - scene.truth_world, axis=1)
    assert np.median(err) < 0.05
