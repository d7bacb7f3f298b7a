"""Rig files: loading, validation (errors name the camera), saving, the example rig."""
import os

from accelcal_ros.camera.rig import load_rig, ring_rig, save_rig
from accelcal_ros.errors import FileFormatError
from accelcal_ros.frames import rot_y
from accelcal_ros.textformats import dump_yaml
import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _camera(name='cam0', r=None, **extra):
    entry = {'name': name, 'width': 320, 'height': 240,
             'K': [275.0, 0, 159.5, 0, 275.0, 119.5, 0, 0, 1],
             'R': (np.eye(3) if r is None else r).reshape(-1).tolist()}
    entry.update(extra)
    return entry


def _write(tmp_path, data):
    path = tmp_path / 'rig.yaml'
    path.write_text(dump_yaml(data) if not isinstance(data, str) else data)
    return path


def test_load_valid_rig_and_defaults(tmp_path):
    """D is optional (zeros); 4 coefficients mean k3 = 0; R is re-orthonormalised."""
    r1 = rot_y(np.radians(-40)).T
    right = _camera('right', r1, D=[-0.1, 0.01, 0.0, 0.0])
    path = _write(tmp_path, {'cameras': [_camera(), right]})
    rig = load_rig(path)
    assert rig.names == ['cam0', 'right']
    assert np.all(rig.cameras[0].D == 0)
    assert rig.cameras[1].D.tolist() == [-0.1, 0.01, 0.0, 0.0, 0.0]
    assert np.allclose(rig.cameras[1].optical_axis_in_reference,
                       [np.sin(np.radians(-40)), 0, np.cos(np.radians(-40))])


@pytest.mark.parametrize('mutate, words', [
    (lambda c: c[1].pop('K'), r"camera 1 \('cam1'\): missing key\(s\) K"),
    (lambda c: c[1].pop('R'), r"camera 1 \('cam1'\): missing key\(s\) R"),
    (lambda c: c[1].update(R=[1, 0, 0, 0, 1, 0, 0, 0, 2]), r"camera 1 \('cam1'\): R: not a "
                                                           'rotation'),
    (lambda c: c[1].update(R=[1, 0, 0, 0, -1, 0, 0, 0, 1]), "'cam1'.*not a rotation"),
    (lambda c: c[1].update(R=[1, 0, 0]), "'cam1'.*R needs 9 values"),
    (lambda c: c[1].update(K=[0, 0, 1, 0, 1, 1, 0, 0, 1]), "'cam1'.*fx, fy > 0"),
    (lambda c: c[1].update(D=[0.1, 0.2]), "'cam1'.*D needs"),
    (lambda c: c[1].update(width=0), "'cam1'.*width"),
    (lambda c: c[1].update(name='cam0'), 'unique'),
    (lambda c: c[1].update(fx=3), "'cam1'.*unknown key"),
    (lambda c: c[0].update(R=rot_y(0.1).reshape(-1).tolist()), 'reference camera'),
    (lambda c: c[1].update(K=[1, 0, 0, 0, 1, 0, 0, 0, float('nan')]), 'NaN'),
])
def test_bad_rig_errors_name_file_camera_and_key(tmp_path, mutate, words):
    """Missing keys, non-rotations and bad values raise FileFormatError naming the camera."""
    cams = [_camera(), _camera('cam1', rot_y(0.5).T)]
    mutate(cams)
    path = _write(tmp_path, {'cameras': cams})
    with pytest.raises(FileFormatError, match=words) as info:
        load_rig(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize('text, words', [
    ('', 'mapping'), ('cameras: []\n', 'non-empty list'), ('other: 1\n', 'missing key'),
    ('cameras: [1, 2]\n', 'camera 0: expected a mapping'), ('cameras: [\n', 'YAML')])
def test_malformed_rig_files(tmp_path, text, words):
    """Empty, truncated or wrongly shaped files are reported, not crashed on."""
    with pytest.raises(FileFormatError, match=words):
        load_rig(_write(tmp_path, text))
    with pytest.raises(FileFormatError, match='not found'):
        load_rig(tmp_path / 'missing.yaml')


def test_save_load_round_trip(tmp_path):
    """save_rig writes what load_rig reads back."""
    rig = ring_rig(4, 640, 480, 500.0, 40.0, distortion=(-0.1, 0.02, 0.001, 0.0, 0.0),
                   mount_error_deg=0.5)
    save_rig(tmp_path / 'r.yaml', rig)
    back = load_rig(tmp_path / 'r.yaml')
    for a, b in zip(rig.cameras, back.cameras):
        assert np.allclose(a.R, b.R, atol=1e-12) and np.allclose(a.K, b.K)
        assert np.allclose(a.D, b.D) and a.name == b.name


def test_example_rig_loads():
    """config/rig_example.yaml is a valid 5-camera rig of 1280x960."""
    rig = load_rig(os.path.join(ROOT, 'config', 'rig_example.yaml'))
    assert len(rig) == 5 and all(c.size == (1280, 960) for c in rig.cameras)
