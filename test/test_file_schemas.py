"""Every file format states its keys and columns: others refused; own output reads back."""
import argparse
import os

from accelcal_ros.boresight_file import load_boresight
from accelcal_ros.camera import CameraModel
from accelcal_ros.camera.camera_info import load_camera_info, save_camera_info
from accelcal_ros.errors import FileFormatError, InputError
from accelcal_ros.lidar.geotraj import read_trajectory_csv
from accelcal_ros.lidar.imu_log import read_imu_csv
from accelcal_ros.lidar.poses import read_poses_csv
from accelcal_ros.panorama.view_cli import ViewPath
from accelcal_ros.rig.intrinsics import load_camera_info as load_rig_intrinsics
from accelcal_ros.schema import check_mapping, CSV_FORMATS, is_integer, Key, numbers
from accelcal_ros.sensor.recording import load_recording
from accelcal_ros.sensor.tilt_series import read_odometry_csv
import numpy as np
import pytest
import yaml

CAMERA_INFO = {
    'image_width': 640, 'image_height': 480, 'camera_name': 'cam0',
    'camera_matrix': {'rows': 3, 'cols': 3, 'data': [500.0, 0, 319.5, 0, 500.0, 239.5, 0, 0, 1]},
    'distortion_model': 'plumb_bob',
    'distortion_coefficients': {'rows': 1, 'cols': 5, 'data': [0.01, 0, 0, 0, 0]},
    'rectification_matrix': {'rows': 3, 'cols': 3, 'data': [1, 0, 0, 0, 1, 0, 0, 0, 1]},
    'projection_matrix': {'rows': 3, 'cols': 4,
                          'data': [500.0, 0, 319.5, 0, 0, 500.0, 239.5, 0, 0, 0, 1, 0]},
}
BORESIGHT = {'R': [1.0, 0, 0, 0, 1, 0, 0, 0, 1], 'rpy_deg': [0.0, 0.0, 0.0],
             'rpy_std_deg': [0.01, 0.01, 0.02], 'positions': ['pos00', 'pos01'],
             'dropped': {}, 'warnings': []}


def _yaml(tmp_path, data, name='f.yaml'):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return str(path)


def _refused(reader, path, *words):
    with pytest.raises(FileFormatError) as info:
        reader(path)
    text = str(info.value)
    assert '\n' not in text and str(path) in text
    for word in words:
        assert word in text, text
    return info.value


YAML_READERS = [('boresight', load_boresight, BORESIGHT, 'R'),
                ('camera_info', lambda p: load_camera_info(p), CAMERA_INFO, 'camera_matrix'),
                ('rig intrinsics', load_rig_intrinsics, CAMERA_INFO, 'image_width')]


@pytest.mark.parametrize('name,reader,good,required', YAML_READERS,
                         ids=[r[0] for r in YAML_READERS])
def test_yaml_formats_refuse_unknown_missing_and_wrong_types(tmp_path, name, reader, good,
                                                             required):
    """Each YAML format: the good file reads; an unknown key, a missing one, a bool refused."""
    reader(_yaml(tmp_path, good))
    _refused(reader, _yaml(tmp_path, dict(good, misspelt_key=1)), 'unknown key', 'misspelt_key')
    missing = {k: v for k, v in good.items() if k != required}
    if name == 'boresight':  # R or rpy_deg: one of them is required
        missing = {k: v for k, v in missing.items() if k != 'rpy_deg'}
    _refused(reader, _yaml(tmp_path, missing), required)
    first = next(iter(good))
    wrong = dict(good)
    wrong[first] = True if not isinstance(good[first], bool) else 'yes'
    _refused(reader, _yaml(tmp_path, wrong), first)


def test_camera_info_nested_keys_and_types(tmp_path):
    """camera_matrix.rows missing, a text width, an unknown nested key: each named."""
    bad = dict(CAMERA_INFO,
               camera_matrix={'cols': 3, 'data': CAMERA_INFO['camera_matrix']['data']})
    _refused(load_camera_info, _yaml(tmp_path, bad), 'camera_matrix.rows')
    bad = dict(CAMERA_INFO, image_width='640')
    _refused(load_camera_info, _yaml(tmp_path, bad), 'image_width', 'integer')
    bad = dict(CAMERA_INFO, camera_matrix=dict(CAMERA_INFO['camera_matrix'], step=1))
    _refused(load_camera_info, _yaml(tmp_path, bad), 'camera_matrix.step')
    bad = dict(CAMERA_INFO, distortion_model='fisheye')
    _refused(load_camera_info, _yaml(tmp_path, bad), 'distortion_model')
    bad = dict(CAMERA_INFO, projection_matrix={'rows': 3, 'cols': 4, 'data': [1, 'x']})
    _refused(load_camera_info, _yaml(tmp_path, bad), 'projection_matrix.data')


def test_boresight_report_fields_are_typed(tmp_path):
    """A report field of the wrong type (text warnings as a number) is refused."""
    _refused(load_boresight, _yaml(tmp_path, dict(BORESIGHT, warnings=3)), 'warnings')
    _refused(load_boresight, _yaml(tmp_path, dict(BORESIGHT, rpy_std_deg=[1, 2])),
             'rpy_std_deg')


def test_check_mapping_rules():
    """The schema check itself: required null is missing, nested paths dotted."""
    schema = {'a': Key('an integer', is_integer, required=True),
              'b': Key('a matrix', schema={'data': Key('numbers', numbers(), required=True)})}
    check_mapping({'a': 1, 'b': {'data': [1.0]}}, schema, 'a test file')
    with pytest.raises(InputError, match='missing key.*a'):
        check_mapping({'a': None}, schema, 'a test file')
    with pytest.raises(InputError, match='b.data'):
        check_mapping({'a': 1, 'b': {'data': [True]}}, schema, 'a test file')
    with pytest.raises(InputError, match='b must be a mapping'):
        check_mapping({'a': 1, 'b': [1]}, schema, 'a test file')
    # a text file read as YAML: one "key" a line; the reason names five, short, and counts
    lines = {f'user{k}:*:20228:0:99999:7:::' + 'x' * 60: None for k in range(300)}
    with pytest.raises(InputError) as caught:
        check_mapping(dict(lines, a=1), schema, 'a test file')
    assert 'and 295 more' in str(caught.value) and len(str(caught.value)) < 400


CSV_READERS = [
    ('recording', load_recording, 't,ax,ay,az', '0,0,0,9.8\n0.01,0,0,9.8\n'),
    ('imu log', read_imu_csv, 't,ax,ay,az,gx,gy,gz', '0,0,0,9.8,0,0,0\n0.01,0,0,9.8,0,0,0\n'),
    ('odometry', read_odometry_csv, 't,v,yaw_rate', '0,1,0\n0.1,1,0\n'),
    ('poses', read_poses_csv, 't,x,y,z,qx,qy,qz,qw', '0,0,0,0,0,0,0,1\n1,1,0,0,0,0,0,1\n'),
    ('trajectory', read_trajectory_csv, 't,lat,lon,h,roll,pitch,yaw',
     '0,55.7,37.6,150,0,0,0\n1,55.7,37.6001,150,0,0,0\n'),
    ('view path', ViewPath.load, 't,azimuth,elevation,fov_h', '0,0,0,60\n1,10,0,60\n'),
]


@pytest.mark.parametrize('name,reader,header,rows', CSV_READERS, ids=[r[0] for r in CSV_READERS])
def test_csv_formats_refuse_unknown_missing_and_wrong_types(tmp_path, name, reader, header,
                                                            rows):
    """Each CSV: reads; an extra column, a missing one, a doubled one, text: one line each."""
    path = tmp_path / 'f.csv'
    path.write_text(f'{header}\n{rows}')
    reader(str(path))
    path.write_text(f'{header},extra\n' + ''.join(r + ',1\n' for r in rows.splitlines()))
    _refused(reader, str(path), 'unknown column', 'extra')
    # a header of 100 000 columns: the reason names five (it was a 10.9 MB line)
    path.write_text(header + ''.join(f',x{k}' for k in range(100000)) + '\n')
    _refused(reader, str(path), 'and 99995 more')
    with pytest.raises(FileFormatError) as caught:
        reader(str(path))
    assert len(str(caught.value)) < 500
    cols = header.split(',')
    path.write_text(','.join(cols[:1] + cols[2:]) + '\n' + ''.join(
        ','.join(r.split(',')[:1] + r.split(',')[2:]) + '\n' for r in rows.splitlines()))
    _refused(reader, str(path), 'lacks column', cols[1])
    path.write_text(f'{header},{cols[1]}\n' + ''.join(r + ',0\n' for r in rows.splitlines()))
    _refused(reader, str(path), 'more than once')
    first, second = rows.splitlines()
    path.write_text(f'{header}\n{first}\n' + second.rsplit(',', 1)[0] + ',true\n')
    error = _refused(reader, str(path), 'non-numeric')
    assert error.line == 3


def test_partial_gyro_columns_are_refused(tmp_path):
    """gx,gy without gz is no gyro: refused, not silently ignored."""
    path = tmp_path / 'imu.csv'
    path.write_text('t,ax,ay,az,gx,gy\n0,0,0,9.8,0,0\n0.01,0,0,9.8,0,0\n')
    _refused(read_imu_csv, str(path), 'gx,gy,gz')


def test_every_csv_format_has_a_reader_test():
    """The tests above cover every registered CSV format (a new one needs its row here)."""
    headers = [r[2] for r in CSV_READERS]
    for fmt in CSV_FORMATS.values():
        assert any(h.startswith(','.join(fmt.required)) for h in headers), fmt.name


def test_own_writers_and_sample_data_read_back(tmp_path, capsys):
    """What the package writes (sample data, camera_info, boresight, drive CSVs) reads back."""
    from accelcal_ros.attitude.cli import _write_drive
    from accelcal_ros.cli import main

    assert main(['sample-data', str(tmp_path), '--only', 'imu', 'lidar', 'map']) == 0
    t, accel = load_recording(str(tmp_path / 'rec.csv'))
    assert t.size > 100 and 7.0 < np.linalg.norm(accel, axis=1).mean() < 12.0  # uncalibrated
    assert read_poses_csv(str(tmp_path / 'poses.csv')).t.size >= 2
    assert read_trajectory_csv(str(tmp_path / 'drive_trajectory.csv')).t.size >= 2
    load_boresight(str(tmp_path / 'drive_boresight.yaml'))
    positions = tmp_path / 'boresight_positions'
    for name in sorted(os.listdir(positions)):
        if name.endswith('_imu.csv'):
            assert read_imu_csv(str(positions / name)).t.size > 0
    out = tmp_path / 'boresight.yaml'
    assert main(['boresight', str(positions), '-o', str(out)]) == 0
    np.testing.assert_allclose(np.linalg.det(load_boresight(str(out))), 1.0, atol=1e-6)
    model = CameraModel(640, 480, np.array([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]]),
                        np.array([0.01, -0.002, 0.0, 0.0, 0.0]))
    save_camera_info(str(tmp_path / 'cam.yaml'), 'cam0', model)
    name, back = load_camera_info(str(tmp_path / 'cam.yaml'))
    assert name == 'cam0' and np.allclose(back.K, model.K) and np.allclose(back.D, model.D)
    args = argparse.Namespace(rates=[100.0], seed=0, drive_out=str(tmp_path / 'drive.csv'),
                              odometry_out=str(tmp_path / 'odo.csv'))
    _write_drive(args)
    assert read_imu_csv(str(tmp_path / 'drive.csv')).gyro is not None
    assert load_recording(str(tmp_path / 'drive.csv'))[0].size > 0
    assert read_odometry_csv(str(tmp_path / 'odo.csv'))[0].size >= 2
    capsys.readouterr()


def test_docs_list_every_key_and_column():
    """docs/formats.md names every key of every schema and every CSV format's columns."""
    from accelcal_ros import boresight_file
    from accelcal_ros.camera import camera_info
    from accelcal_ros.camera.rig import CAMERA_ENTRY_KEYS
    from accelcal_ros.schema import schema_table
    from accelcal_ros.sensor import calibration_file

    text = open(os.path.join(os.path.dirname(__file__), '..', 'docs', 'formats.md')).read()
    keys = [row[0] for row in schema_table(boresight_file.SCHEMA)]
    keys += [row[0] for row in schema_table(camera_info.SCHEMA)]
    keys += list(calibration_file.SCHEMA) + list(CAMERA_ENTRY_KEYS)
    for key in keys:
        assert f'`{key}`' in text, key
    for fmt in CSV_FORMATS.values():
        assert f'`{",".join(fmt.required)}`' in text, fmt.name
