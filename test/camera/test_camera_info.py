"""camera_info YAML (camera_calibration_parsers' format): written, read back exactly, checked."""
from accelcal_ros.camera.camera_info import (load_camera_info, rig_with_models,
                                             save_camera_info)
from accelcal_ros.camera.model import CameraModel
from accelcal_ros.camera.rig import ring_rig
from accelcal_ros.errors import FileFormatError, InputError
import numpy as np
import pytest
import yaml

K = np.array([[1101.123456789012, 0.0, 640.5123456789],
              [0.0, 1099.87654321, 479.25], [0.0, 0.0, 1.0]])
LENSES = [('plumb_bob', [-0.2812345678901, 0.0912345, 1.2e-4, -3.4e-5, -0.0123]),
          ('rational_polynomial', [0.1, -0.2, 1e-4, 2e-4, 0.03, 0.11, -0.19, 0.028]),
          ('equidistant', [0.01, -0.002, 3e-4, -1e-5])]


def _documented_reader(path):
    """Read the file as camera_calibration_parsers documents it (rows, cols, row-major data)."""
    with open(path) as handle:
        doc = yaml.safe_load(handle)

    def matrix(key):
        entry = doc[key]
        return np.array(entry['data'], dtype=float).reshape(entry['rows'], entry['cols'])
    return (doc['camera_name'], doc['image_width'], doc['image_height'],
            matrix('camera_matrix'), doc['distortion_model'],
            matrix('distortion_coefficients').reshape(-1), matrix('rectification_matrix'),
            matrix('projection_matrix'))


@pytest.mark.parametrize('lens, d', LENSES)
def test_written_file_reads_back_k_and_d_exactly(tmp_path, lens, d):
    """Both the documented reader and load_camera_info reproduce K and D bit for bit."""
    model = CameraModel(1280, 960, K, np.array(d), lens)
    path = tmp_path / 'cam0.yaml'
    save_camera_info(path, 'cam0', model)
    name, width, height, k, dist_model, dist, rect, proj = _documented_reader(path)
    assert (name, width, height, dist_model) == ('cam0', 1280, 960, lens)
    assert np.array_equal(k, K) and np.array_equal(dist, np.array(d))
    assert np.array_equal(rect, np.eye(3)) and np.array_equal(proj, np.hstack([K, [[0]] * 3]))
    name, back = load_camera_info(path)
    assert name == 'cam0' and back.size == (1280, 960) and back.distortion_model == lens
    assert np.array_equal(back.K, K) and np.array_equal(back.D, np.array(d))


@pytest.mark.parametrize('edit, reason', [
    (lambda doc: doc['camera_matrix'].update(rows=2), 'must be 3x3'),
    (lambda doc: doc['projection_matrix']['data'].pop(), 'needs 12 values'),
    (lambda doc: doc['distortion_coefficients'].update(cols=4), '1x4 but 5 values'),
    (lambda doc: doc.update(distortion_model='pinhole'), 'distortion_model'),
    (lambda doc: doc.pop('camera_matrix'), 'missing key'),
    (lambda doc: doc.update(image_width=-3), 'image_width')])
def test_bad_files_name_the_file_and_the_key(tmp_path, edit, reason):
    """A wrong shape, model or missing key: FileFormatError naming the file and what."""
    path = tmp_path / 'cam.yaml'
    save_camera_info(path, 'cam', CameraModel(1280, 960, K, np.array(LENSES[0][1])))
    doc = yaml.safe_load(path.read_text())
    edit(doc)
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(FileFormatError, match=reason) as info:
        load_camera_info(path)
    assert 'cam.yaml' in str(info.value)


def test_a_principal_point_outside_the_image_is_refused():
    """
    Refuse ``cx = 5000`` for a 640 px image (another camera's K), naming point and size.

    It was accepted (P2P ranges 62.9 and 362.7 m for a true 6.1 m, status 0).
    """
    with pytest.raises(InputError, match=r'camera_info K: the principal point \(5000, 479.25\) '
                                         r'px lies outside the 640x480 image'):
        CameraModel.from_camera_info([600, 0, 5000, 0, 600, 479.25, 0, 0, 1], [], '', 640, 480)
    with pytest.raises(InputError, match='outside the 640x480'):
        CameraModel(640, 480, K)
    assert CameraModel(0, 0, K).K[0, 2] == K[0, 2]   # size unknown: not checked


def test_rig_takes_camera_info_intrinsics_of_the_right_size():
    """rig_with_models swaps K and D, keeps R and imu_to_camera; a wrong size is refused."""
    rig = ring_rig(2, width=1280, height=960)
    model = CameraModel.from_camera_info(K.reshape(-1), LENSES[0][1], 'plumb_bob', 1280, 960)
    swapped = rig_with_models(rig, [model, model], ['a/camera_info', 'b/camera_info'])
    assert np.array_equal(swapped.cameras[1].K, K)
    assert np.array_equal(swapped.cameras[1].R, rig.cameras[1].R)
    half = np.diag([0.5, 0.5, 1.0]) @ K
    small = CameraModel.from_camera_info(half.reshape(-1), [], '', 640, 480)
    with pytest.raises(InputError, match='b/camera_info: camera_info is 640x480'):
        rig_with_models(rig, [model, small], ['a/camera_info', 'b/camera_info'])
