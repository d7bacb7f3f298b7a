"""Rig files no calibration wrote are refused with the camera and key (issue 26)."""
import copy

from accelcal_ros.camera.rig import load_rig
from accelcal_ros.errors import FileFormatError
from accelcal_ros.textformats import dump_yaml
import pytest

K = [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0]
EYE = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
YAW = [0.0, 0.0, -1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0]  # rot_y(90 deg)^T
GOOD = {'cameras': [
    {'name': 'cam0', 'width': 640, 'height': 480, 'K': K, 'D': [0.01, -0.02, 0, 0, 0],
     'R': EYE},
    {'name': 'cam1', 'width': 640, 'height': 480, 'K': K, 'D': [0, 0, 0, 0, 0], 'R': YAW}]}


def _with(camera, key, value):
    data = copy.deepcopy(GOOD)
    data['cameras'][camera][key] = value
    return data


@pytest.mark.parametrize('data, reason', [
    (_with(1, 'D', [1e6, 0, 0, 0, 0]), r"camera 1 \('cam1'\): D .* beyond \+-1000"),
    (_with(1, 'R', EYE), 'all 2 cameras of the rig have the same R'),
    (_with(0, 'K', [500.0, 0.0, -1e308, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0]),
     r"camera 0 \('cam0'\): K = .* is not a camera"),
    (_with(0, 'K', [1e300, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0]), 'is not a camera'),
    (_with(0, 'K', [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1e-320]),
     'is not a camera|K must be'),
    (_with(0, 'K', [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1e308]),
     'is not a camera'),  # fuzz: fx = 5e-306 px after K /= K[2, 2]
    (_with(1, 'D', [True, 0, 0, 0, 0]), 'D must contain numbers only'),
    (_with(1, 'R', [True if v == 1.0 else v for v in YAW]), 'R must contain numbers only'),
    (_with(0, 'width', True), 'width must be an integer'),
])
def test_absurd_rig_files_are_refused(tmp_path, data, reason):
    """D = 1e6, every camera with one R, a K entry of -1e308, bools: one clear error."""
    path = tmp_path / 'rig.yaml'
    path.write_text(dump_yaml(data))
    with pytest.raises(FileFormatError, match=reason) as info:
        load_rig(path)
    assert str(path) in str(info.value) and '\n' not in str(info.value)


def test_the_good_rig_and_yaml12_exponents_load(tmp_path):
    """The valid file loads; ``1e-3`` (text in YAML 1.1) is a number as in YAML 1.2."""
    path = tmp_path / 'rig.yaml'
    path.write_text(dump_yaml(GOOD).replace('0.01', '1e-2'))
    rig = load_rig(path)
    assert rig.cameras[0].D[0] == pytest.approx(0.01)


def test_stitch_with_a_k_entry_of_minus_1e308_is_one_line(tmp_path, capsys, monkeypatch):
    """`accelcal stitch --rig` with cx = -1e308: status 1, one error line, not internal."""
    import cv2
    import numpy as np

    from accelcal_ros.cli import main

    monkeypatch.chdir(tmp_path)
    (tmp_path / 'rig.yaml').write_text(dump_yaml(_with(
        0, 'K', [500.0, 0.0, -1e308, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0])))
    for k in range(2):
        cv2.imwrite(f'img{k}.png', np.full((480, 640, 3), 100, np.uint8))
    status = main(['stitch', '--rig', 'rig.yaml', '--roll', '0', '--pitch', '0', '--width',
                   '64', '--height', '32', '-o', 'out.png', 'img0.png', 'img1.png'])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 1 and len(err) == 1 and 'internal' not in err[0], err
    assert 'is not a camera' in err[0]
