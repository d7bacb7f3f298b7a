"""The rig file's optional imu_to_camera: read, written, validated, and who wins."""
from accelcal_ros.camera.rig import load_rig, resolve_imu_to_camera, RigCamera, ring_rig, save_rig
from accelcal_ros.errors import FileFormatError, InputError
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rot_x, rot_z
from accelcal_ros.panorama.projection import PanoramaGeometry
from accelcal_ros.panorama.stitch import Stitcher
from accelcal_ros.textformats import dump_yaml, load_yaml_mapping
import numpy as np
import pytest

MOUNT = rot_x(0.02) @ rot_z(0.1) @ DEFAULT_IMU_TO_CAMERA


def test_round_trip_and_absent_default(tmp_path):
    """Written row-major, read back as a rotation; absent: None, and not written."""
    save_rig(tmp_path / 'a.yaml', ring_rig(3, 320, 240, 275.0, imu_to_camera=MOUNT))
    data = load_yaml_mapping(tmp_path / 'a.yaml', what='rig file')
    assert len(data['imu_to_camera']) == 9
    assert np.allclose(load_rig(tmp_path / 'a.yaml').imu_to_camera, MOUNT, atol=1e-12)
    save_rig(tmp_path / 'b.yaml', ring_rig(3, 320, 240, 275.0))
    assert 'imu_to_camera' not in load_yaml_mapping(tmp_path / 'b.yaml', what='rig file')
    assert load_rig(tmp_path / 'b.yaml').imu_to_camera is None


@pytest.mark.parametrize('value, words', [
    ([1, 0, 0, 0, 1, 0, 0, 0, float('nan')], 'imu_to_camera contains NaN'),
    ([1, 0, 0, 0, 1, 0], 'imu_to_camera needs 9 values'),
    ([2, 0, 0, 0, 1, 0, 0, 0, 1], 'imu_to_camera: not a rotation'),
    ([-1, 0, 0, 0, 1, 0, 0, 0, 1], 'imu_to_camera: not a rotation'),
    ('identity', 'imu_to_camera must be a list of numbers'),
])
def test_bad_imu_to_camera_names_file_and_key(tmp_path, value, words):
    """NaN, wrong size, non-rotation: FileFormatError naming the file and the key."""
    data = {'cameras': [{'name': 'cam0', 'width': 64, 'height': 48,
                         'K': [50.0, 0, 31.5, 0, 50.0, 23.5, 0, 0, 1],
                         'R': np.eye(3).reshape(-1).tolist()}], 'imu_to_camera': value}
    path = tmp_path / 'rig.yaml'
    path.write_text(dump_yaml(data))
    with pytest.raises(FileFormatError, match=words) as info:
        load_rig(path)
    assert str(path) in str(info.value)


def test_unknown_top_level_key_and_fisheye_entry(tmp_path):
    """A misspelt top-level key is refused; a camera may say distortion_model."""
    cam = {'name': 'cam0', 'width': 64, 'height': 48,
           'K': [50.0, 0, 31.5, 0, 50.0, 23.5, 0, 0, 1],
           'D': [0.01, 0.0, 0.0, 0.0], 'distortion_model': 'equidistant',
           'R': np.eye(3).reshape(-1).tolist()}
    path = tmp_path / 'rig.yaml'
    path.write_text(dump_yaml({'cameras': [cam], 'imu_to_camra': [1, 0, 0]}))
    with pytest.raises(FileFormatError, match='unknown key.*imu_to_camra'):
        load_rig(path)
    path.write_text(dump_yaml({'cameras': [cam]}))
    rig = load_rig(path)
    assert rig.cameras[0].distortion_model == 'equidistant'
    save_rig(tmp_path / 'again.yaml', rig)
    assert load_rig(tmp_path / 'again.yaml').cameras[0].D.tolist() == [0.01, 0.0, 0.0, 0.0]
    with pytest.raises(InputError, match='plumb_bob'):
        Stitcher(rig, PanoramaGeometry(90, 60))


def test_explicit_value_wins_over_the_file_and_the_stitcher_uses_the_file():
    """resolve_imu_to_camera: option > rig file > default; Stitcher defaults to the file."""
    rig = ring_rig(2, 320, 240, 275.0, imu_to_camera=MOUNT)
    mount, source = resolve_imu_to_camera(rig)
    assert source == 'rig file' and np.allclose(mount, MOUNT)
    mount, source = resolve_imu_to_camera(rig, DEFAULT_IMU_TO_CAMERA.reshape(-1))
    assert source == '--imu-to-camera' and np.allclose(mount, DEFAULT_IMU_TO_CAMERA)
    assert resolve_imu_to_camera(ring_rig(2, 320, 240, 275.0))[1] == 'default'
    with pytest.raises(InputError, match='--imu-to-camera: not a rotation'):
        resolve_imu_to_camera(rig, [1, 0, 0, 0, 1, 0, 0, 0, -1])
    stitcher = Stitcher(rig, PanoramaGeometry(180, 120))
    assert np.allclose(stitcher.builder.imu_to_camera, MOUNT)
    assert RigCamera.from_model('x', rig.cameras[0].model, np.eye(3)).K is rig.cameras[0].K
