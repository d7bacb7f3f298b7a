"""Inputs that used to give silent wrong results: mismatched calibration, NaN files."""
from accelcal_ros.lidar import scanner_sim as sim
from accelcal_ros.lidar.boresight import calibrate_boresight
from accelcal_ros.lidar.calibrate_dir import report_lines
from accelcal_ros.lidar.wahba import rotation_angle_deg
from accelcal_ros.sensor.model import SensorModel
import pytest

TRUTH = sim.default_boresight()


@pytest.fixture(scope='module')
def distorted_protocol():
    """Paper B's protocol read by an accelerometer with scale and bias errors."""
    true_model = SensorModel([1.02, 0.98, 1.01], [0.02, -0.015, 0.01], [0.0, 0.0, 0.0])
    return true_model, sim.simulate_protocol(TRUTH, seed=8, imu_model=true_model,
                                             still_s=3.0)


def test_mismatched_calibration_is_reported(distorted_protocol):
    """Another sensor's calibration: |g| off 1 g is named per position with advice."""
    true_model, protocol = distorted_protocol
    wrong = SensorModel([0.93, 1.06, 1.04], [0.05, -0.04, 0.06], [0.0, 0.0, 0.0])
    res = calibrate_boresight(sim.positions_for_calibration(protocol, wrong),
                              sim.nominal_mount())
    text = '\n'.join(report_lines(res))
    assert 'warning: the accelerometer calibration does not fit' in text
    assert 'check that the calibration file' in text and 'pos01' in text
    good = calibrate_boresight(sim.positions_for_calibration(protocol, true_model),
                               sim.nominal_mount())
    assert not any('calibration does not fit' in w for w in good.warnings)
    assert rotation_angle_deg(good.rotation, TRUTH) < 0.05
    # without a calibration nothing is claimed about |g|
    raw = calibrate_boresight(sim.positions_for_calibration(protocol), sim.nominal_mount())
    assert not any('calibration does not fit' in w for w in raw.warnings)


@pytest.mark.parametrize('fields, match', [
    ({'rpy_deg': [float('nan'), 2, 3]}, 'rpy_deg: contains NaN'),
    ({'rpy_deg': [1, 2]}, 'rpy_deg: expected 3 numbers'),
    ({'rpy_deg': ['a', 2, 3]}, 'rpy_deg: expected 3 numbers'),
    ({'rpy_deg': [1, 95, 3]}, 'pitch 95 deg is outside'),
    ({'rpy_deg': [1e300, 0, 0]}, 'roll 1e\\+300 deg is outside'),
    ({'R': [1, 0, 0, 0, 1, 0, 0, 0, float('inf')]}, 'R: contains NaN'),
    ({'R': [1, 0, 0, 0, 1, 0, 0, 0]}, 'R: expected 9 numbers'),
    ({'R': [2, 0, 0, 0, 1, 0, 0, 0, 1]}, 'not a rotation'),
    ({'R': [1, 0, 0, 0, 1, 0, 0, 0, 1], 'rpy_deg': [0, 10, 0]}, 'disagree by 10.000 deg'),
    ({'rpy_std_deg': [0, 0, 0]}, 'neither R'),
])
def test_boresight_file_fields_validated(tmp_path, fields, match):
    """Every field of the boresight file is checked where it is read, naming file and field."""
    from accelcal_ros.errors import FileFormatError
    from accelcal_ros.fileio import write_text_atomic
    from accelcal_ros.textformats import dump_yaml
    from accelcal_ros.lidar.boresight import load_boresight

    path = tmp_path / 'bs.yaml'
    write_text_atomic(path, dump_yaml(fields))
    with pytest.raises(FileFormatError, match=match) as err:
        load_boresight(path)
    assert str(path) in str(err.value)


def _georef_inputs(tmp_path, points=100):
    from accelcal_ros.lidar.cloud import make_cloud
    from accelcal_ros.lidar.pcd import write_pcd
    from accelcal_ros.lidar.poses import PoseStream, write_poses_csv
    import numpy as np

    rng = np.random.default_rng(0)
    write_pcd(tmp_path / 'scan.pcd', make_cloud(rng.normal(size=(points, 3)), None, None,
                                                np.linspace(0, 0.09, points)), 'binary')
    write_poses_csv(tmp_path / 'poses.csv', PoseStream([9.0, 11.0], np.zeros((2, 3)),
                                                       [[0, 0, 0, 1.0]] * 2))
    return ['georeference', '--cloud', str(tmp_path / 'scan.pcd'), '--poses',
            str(tmp_path / 'poses.csv'), '--time-base', '10.0', '-o', str(tmp_path / 'o.ply')]


def test_georeference_refuses_nan_boresight_and_empty_cloud(tmp_path, capsys):
    """A NaN boresight: exit 1 naming file and field, nothing written; same for 0 points."""
    from accelcal_ros.cli import main
    from accelcal_ros.fileio import write_text_atomic
    from accelcal_ros.textformats import dump_yaml

    args = _georef_inputs(tmp_path)
    write_text_atomic(tmp_path / 'nan.yaml', dump_yaml({'rpy_deg': [float('nan'), 2.0, 3.0]}))
    write_text_atomic(tmp_path / 'ok.yaml', dump_yaml({'rpy_deg': [1.0, 2.0, 3.0]}))
    assert main(args + ['--boresight', str(tmp_path / 'nan.yaml')]) == 1
    err = capsys.readouterr().err
    assert 'nan.yaml' in err and 'rpy_deg' in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / 'o.ply').exists()
    assert main(args + ['--boresight', str(tmp_path / 'ok.yaml')]) == 0
    (tmp_path / 'empty').mkdir()
    empty = _georef_inputs(tmp_path / 'empty', 0)
    assert main(empty + ['--boresight', str(tmp_path / 'ok.yaml')]) == 1
    err = capsys.readouterr().err
    assert 'no points' in err and 'Traceback' not in err


@pytest.mark.parametrize('row, match', [
    ('1.5,1e300,0,0,0,0,0,1', 'beyond 1e\\+08 m'),
    ('1.5,0,nan,0,0,0,0,1', 'NaN or infinite'),
    ('1.5e18,0,0,0,0,0,0,1', 'nanoseconds'),
])
def test_pose_file_absurd_values(tmp_path, row, match):
    """Absurd coordinates and times in a pose file are errors naming file and line."""
    from accelcal_ros.errors import FileFormatError
    from accelcal_ros.lidar.poses import read_poses_csv

    path = tmp_path / 'poses.csv'
    path.write_text('t,x,y,z,qx,qy,qz,qw\n1.0,0,0,0,0,0,0,1\n' + row + '\n2.0,0,0,0,0,0,0,1\n')
    with pytest.raises(FileFormatError, match=match) as err:
        read_poses_csv(path)
    assert f'{path}:3' in str(err.value)


def test_cloud_assembler_core_refuses_nan_boresight_and_lever_arm():
    """The streaming core checks its rotation and lever arm once, at construction."""
    from accelcal_ros.errors import InputError
    from accelcal_ros.lidar.assembler import CloudAssembler
    import numpy as np

    with pytest.raises(InputError, match='boresight'):
        CloudAssembler(np.full((3, 3), np.nan))
    with pytest.raises(InputError, match='lever arm'):
        CloudAssembler(np.eye(3), (0.0, float('inf'), 0.0))
    assert CloudAssembler(np.eye(3)).summary().startswith('0 scans')
