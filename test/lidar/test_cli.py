"""``accelcal boresight``, ``georeference`` and ``error-budget`` end to end on files."""
import os

from accelcal_ros.cli import main
from accelcal_ros.fileio import write_text_atomic
from accelcal_ros.lidar import scanner_sim as sim
from accelcal_ros.lidar.boresight import load_boresight
from accelcal_ros.lidar.cloud import make_cloud
from accelcal_ros.lidar.pcd import write_pcd
from accelcal_ros.lidar.ply import read_ply
from accelcal_ros.lidar.poses import write_poses_csv
from accelcal_ros.lidar.wahba import rotation_angle_deg
from accelcal_ros.textformats import dump_yaml, load_yaml_mapping
import numpy as np
import pytest

TRUTH = sim.default_boresight()


@pytest.fixture(scope='module')
def protocol_dir(tmp_path_factory):
    """Paper B's protocol written as posNN.pcd + posNN_imu.csv (mixed PCD encodings)."""
    directory = tmp_path_factory.mktemp('protocol')
    protocol = sim.simulate_protocol(TRUTH, seed=5)
    sim.write_protocol(directory, protocol[:5], 'binary_compressed')
    sim.write_protocol(directory, protocol[5:], 'binary')
    return directory


def test_boresight_cli_writes_yaml(protocol_dir, tmp_path, capsys):
    """The YAML has R, rpy_deg, per-position and hold-out errors; the rotation is right."""
    out = tmp_path / 'bs.yaml'
    assert main(['boresight', str(protocol_dir), '-o', str(out), '--plot',
                 str(tmp_path / 'fig.png')]) == 0
    text = capsys.readouterr().out
    assert 'roll' in text and 'hold-out' in text and 'pos15' in text
    data = load_yaml_mapping(out)
    assert len(data['R']) == 9 and len(data['rpy_deg']) == 3
    assert len(data['per_position_error_deg']) == 15
    assert data['holdout_error_deg']['mean'] < 0.15
    assert rotation_angle_deg(load_boresight(out), TRUTH) < 0.05
    assert (tmp_path / 'fig.png').stat().st_size > 1000
    prior = main(['boresight', str(protocol_dir), '-o', str(tmp_path / 'p.yaml'),
                  '--prior-rpy-deg', '0', '45', '0'])
    assert prior == 0
    assert rotation_angle_deg(load_boresight(tmp_path / 'p.yaml'), TRUTH) < 0.05


def test_boresight_cli_bad_files(protocol_dir, tmp_path, capsys):
    """A truncated file is an error naming it (nothing written); empty clouds are dropped."""
    bad = tmp_path / 'bad'
    bad.mkdir()
    for name in os.listdir(protocol_dir):
        (bad / name).write_bytes((protocol_dir / name).read_bytes())
    write_pcd(bad / 'pos03.pcd', make_cloud(np.zeros((0, 3))))
    raw = (bad / 'pos04_imu.csv').read_bytes()
    cut = raw.rstrip(b'\n')
    cut = cut[:cut.rfind(b'\n') + 1] + b'10.0,0.1,0.2'  # writer killed mid-line
    (bad / 'pos04_imu.csv').write_bytes(cut)
    out = tmp_path / 'bs.yaml'
    assert main(['boresight', str(bad), '-o', str(out)]) == 1
    err = capsys.readouterr().err
    assert 'pos04_imu.csv:' in err and not out.exists()
    assert main(['boresight', str(bad), '-o', str(out), '--skip-bad-files']) == 0
    data = load_yaml_mapping(out)
    assert 'pos03' in data['dropped'] and 'pos04' in data['dropped']
    assert 'empty' in data['dropped']['pos03'] and 'pos04_imu.csv' in data['dropped']['pos04']
    assert len(data['positions']) == 13


def test_georeference_cli(tmp_path, capsys):
    """The georeferenced PLY matches the moving-platform truth; no time field -> error."""
    scene = sim.simulate_moving_platform(0.2, range_noise_m=0.0, pose_margin_s=-0.02)
    write_pcd(tmp_path / 'scan.pcd', scene.cloud, 'binary_compressed')
    write_poses_csv(tmp_path / 'poses.csv', scene.poses)
    write_text_atomic(tmp_path / 'bs.yaml', dump_yaml({'R': scene.boresight.ravel().tolist()}))
    args = ['georeference', '--cloud', str(tmp_path / 'scan.pcd'), '--poses',
            str(tmp_path / 'poses.csv'), '--boresight', str(tmp_path / 'bs.yaml'),
            '--lever-arm', *map(str, scene.lever_arm_m), '--time-base',
            str(scene.scan_start_s), '-o', str(tmp_path / 'out.ply')]
    assert main(args) == 0
    assert 'dropped' in capsys.readouterr().out
    out = read_ply(tmp_path / 'out.ply')
    pts = np.stack([out['x'], out['y'], out['z']], axis=1)
    times = out['timestamp']
    t0, t1 = scene.poses.span
    assert times.min() >= t0 and times.max() <= t1
    rel = scene.cloud['time'].astype(float) + scene.scan_start_s
    truth = scene.truth_world[(rel >= t0) & (rel <= t1)]
    assert len(truth) == len(pts)
    assert np.linalg.norm(pts - truth, axis=1).max() < 2e-3
    write_pcd(tmp_path / 'notime.pcd', make_cloud(np.ones((4, 3))))
    args[2] = str(tmp_path / 'notime.pcd')
    args[-1] = str(tmp_path / 'never.ply')
    assert main(args) == 1
    assert 'no per-point time' in capsys.readouterr().err
    assert not (tmp_path / 'never.ply').exists()


def test_error_budget_cli(capsys):
    """The error budget prints the paper's 1.76 m and 0.56 m."""
    assert main(['error-budget']) == 0
    text = capsys.readouterr().out
    assert '1.76 m before, 0.56 m after' in text


def test_boresight_cli_applies_accelerometer_calibration(tmp_path):
    """``--calibration`` loads issue 3's file and removes the IMU bias before averaging."""
    from accelcal_ros.sensor.model import SensorModel

    model = SensorModel([1.0, 1.0, 1.0], [0.01, -0.012, 0.008], [0.0, 0.0, 0.0])
    protocol = sim.simulate_protocol(TRUTH, seed=6, imu_model=model, still_s=3.0)
    data_dir = tmp_path / 'biased'
    sim.write_protocol(data_dir, protocol, 'binary')
    cal = tmp_path / 'accel.yaml'
    write_text_atomic(cal, dump_yaml({'model': 'full', 'scale': [1.0, 1.0, 1.0],
                                      'bias': [0.01, -0.012, 0.008],
                                      'misalignment': [0.0, 0.0, 0.0]}))
    plain, fixed = tmp_path / 'plain.yaml', tmp_path / 'fixed.yaml'
    prior = ['--prior-rpy-deg', '0', '45', '0']
    assert main(['boresight', str(data_dir), '-o', str(plain), *prior]) == 0
    assert main(['boresight', str(data_dir), '-o', str(fixed), '--calibration', str(cal),
                 *prior]) == 0
    assert rotation_angle_deg(load_boresight(fixed), TRUTH) < 0.05
    assert rotation_angle_deg(load_boresight(plain), TRUTH) > 0.1
    assert main(['boresight', str(data_dir), '-o', str(tmp_path / 'x.yaml'), '--calibration',
                 str(tmp_path / 'missing.yaml')]) == 1
