"""``accelcal p2p-solve`` on hostile input: one error per bad line, bad options refused."""
import io
import json
import warnings

from accelcal_ros.camera.rig import ring_rig, save_rig
from accelcal_ros.cli import main
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rot_z, rpy_radians_from_rotation
from accelcal_ros.p2p import render
from accelcal_ros.textformats import dump_yaml
import numpy as np
import pytest

K = [1000.0, 0.0, 640.0, 0.0, 1000.0, 480.0, 0.0, 0.0, 1.0]
POINTS = [[0.0, 0.0, 0.0], [1.0, 0.5, 0.2]]
MOUNT = rot_z(0.3) @ DEFAULT_IMU_TO_CAMERA  # camera yawed 0.3 rad on the IMU body


def _problem(mount=DEFAULT_IMU_TO_CAMERA):
    """Return ``(json dict with roll/pitch, true translation)`` for a camera on ``mount``."""
    rotation, translation = render.pose_from_camera_attitude(
        0.05, 0.3, np.radians(40.0), [-4.0, 0.5, 2.0], mount)
    cam = np.asarray(POINTS) @ rotation.T + translation
    uv = cam @ np.reshape(K, (3, 3)).T
    body = rotation.T @ mount  # body attitude in the object frame
    roll, pitch, _ = rpy_radians_from_rotation(body)
    return ({'uv': (uv[:, :2] / uv[:, 2:]).tolist(), 'K': K, 'points': POINTS,
             'roll': roll, 'pitch': pitch}, translation)


def _run(monkeypatch, capsys, lines, *args):
    monkeypatch.setattr('sys.stdin', io.StringIO(''.join(line + '\n' for line in lines)))
    status = main(['p2p-solve', *args])
    captured = capsys.readouterr()
    return status, [json.loads(line) for line in captured.out.splitlines()], captured.err


def _closest(record, translation):
    return min(np.linalg.norm(np.subtract(s['t'], translation)) for s in record['solutions'])


@pytest.mark.parametrize('change, words', [
    ({'imu_to_camera': 'abc'}, 'JSON numbers'),
    ({'imu_to_camera': [[1, 2], [3]]}, 'numbers of shape'),
    ({'imu_to_camera': [1, 0, 0]}, 'shape'),
    ({'imu_to_camera': None}, 'JSON numbers'),
    ({'imu_to_camera': ['1', 0, 0, 0, 1, 0, 0, 0, 1]}, 'JSON numbers'),
    ({'imu_to_camera': [True, 0, 0, 0, 1, 0, 0, 0, 1]}, 'JSON numbers'),
    ({'imu_to_camera': [1e308, 0, 0, 0, 1, 0, 0, 0, 1]}, 'not a rotation'),
    ({'imu_to_camera': [1, 0, 0, 0, 1, 0, 0, 0, -1]}, 'not a rotation'),
    ({'imu_to_camera': [2, 0, 0, 0, 1, 0, 0, 0, 1]}, 'not a rotation'),
    ({'K': [-1000.0, 0, 640, 0, 1000, 480, 0, 0, 1]}, 'fx, fy > 0'),
    ({'K': [0.0] * 9}, 'not calibrated'),
    ({'D': [0.1, 0.2, 0.3]}, '4, 5 or 8'),
    ({'pitch': 1e308}, 'within'),
    ({'roll': True}, 'JSON numbers'),
    ({'uv': [[1280, 960], [1200, 960]], 'K': [800, 0, 640, 0, 800, 480, 0, 0, 1],
      'D': [-0.6, 0, 0, 0, 0]}, "pixel (1280, 960) is outside the lens model's valid range"),
    ({'uv': [[700, 500], [1600, 1200]], 'K': [800, 0, 640, 0, 800, 480, 0, 0, 1],
      'D': [-0.6, 0, 0, 0, 0]}, "pixel (1600, 1200) is outside the lens model's valid range"),
    ({'points': [[0, 0, 0], [0, 1e300, 0]]}, 'within +-1,000,000 m'),
    ({'points': [[0, 0, 0], [1e6 + 1, 0.5, 0]]}, 'within +-1,000,000 m'),
])
def test_a_bad_line_gets_one_error_and_the_stream_goes_on(monkeypatch, capsys, change,
                                                          words):
    """Each malformed field: its own error line, no traceback, the next line solved."""
    good, translation = _problem()
    bad = dict(good, **change)
    status, out, err = _run(monkeypatch, capsys, [json.dumps(bad), json.dumps(good)])
    assert status == 1 and len(out) == 2 and err == ''
    assert out[0]['solutions'] == [] and words in out[0]['error']
    assert _closest(out[1], translation) < 1e-9


def test_deeply_nested_json_is_one_error(monkeypatch, capsys):
    """A line nested beyond the parser's recursion limit does not stop the stream."""
    good, translation = _problem()
    status, out, _ = _run(monkeypatch, capsys, ['[' * 100000 + ']' * 100000, json.dumps(good)])
    assert status == 1 and 'nested too deeply' in out[0]['error']
    assert _closest(out[1], translation) < 1e-9


def test_rig_file_mounting_and_option_override(monkeypatch, capsys, tmp_path):
    """--rig's imu_to_camera is the default; --imu-to-camera and the line's own win."""
    save_rig(tmp_path / 'rig.yaml', ring_rig(2, imu_to_camera=MOUNT))
    line, translation = _problem(MOUNT)
    plain = json.dumps(line)
    own = json.dumps(dict(line, imu_to_camera=MOUNT.reshape(-1).tolist()))
    status, out, _ = _run(monkeypatch, capsys, [plain, own], '--rig', str(tmp_path / 'rig.yaml'))
    assert status == 0 and _closest(out[0], translation) < 1e-9
    assert _closest(out[1], translation) < 1e-9
    default = [str(v) for v in DEFAULT_IMU_TO_CAMERA.reshape(-1)]
    status, out, _ = _run(monkeypatch, capsys, [plain, own], '--rig', str(tmp_path / 'rig.yaml'),
                          '--imu-to-camera', *default)
    assert status == 0 and _closest(out[0], translation) > 0.1   # the option won
    assert _closest(out[1], translation) < 1e-9                  # the line's own won


@pytest.mark.parametrize('rig_text, option, words', [
    (None, ['1', '0', '0', '0', '1', '0', '0', '0', '-1'], 'not a rotation'),
    (None, ['9'] * 9, 'not a rotation'),
    ({'imu_to_camera': [1, 0, 0]}, None, 'imu_to_camera needs 9'),
    ({'imu_to_camera': [1, 0, 0, 0, 1, 0, 0, 0, float('nan')]}, None, 'NaN'),
    ({'imu_to_camera': [0, 1, 0, 1, 0, 0, 0, 0, 1]}, None, 'not a rotation'),
    ({'imu_to_camera': 'x'}, None, 'list of numbers'),
])
def test_a_bad_mounting_is_refused_up_front(monkeypatch, capsys, tmp_path, rig_text, option,
                                            words):
    """A bad rig file or --imu-to-camera: one error line before any input is read."""
    args = []
    if rig_text is not None:
        data = {'cameras': [{'name': 'cam0', 'width': 64, 'height': 48, 'K': K,
                             'R': np.eye(3).reshape(-1).tolist()}], **rig_text}
        (tmp_path / 'rig.yaml').write_text(dump_yaml(data))
        args += ['--rig', str(tmp_path / 'rig.yaml')]
    if option is not None:
        args += ['--imu-to-camera', *option]
    line, _ = _problem()
    status, out, err = _run(monkeypatch, capsys, [json.dumps(line)], *args)
    assert status != 0 and out == []
    assert words in err and 'Traceback' not in err and len(err.strip().splitlines()) == 1


def test_a_pixel_past_the_lens_fold_is_its_own_error_not_a_pose(monkeypatch, capsys):
    """
    The line of the bug report: one error for it, exit 1, no pose.

    The old code answered with a pose whose projection through K and D put the emitters
    at (459.6, 344.7) and (908.1, 709.8), not at the input pixels.
    """
    line = ('{"uv": [[1280, 960], [1200, 960]], "K": [800,0,640, 0,800,480, 0,0,1], '
            '"points": [[0,0,0], [0,0.5,0]], "down": [0,1,0], "D": [-0.6,0,0,0,0]}')
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        status, out, err = _run(monkeypatch, capsys, [line])
    assert status == 1 and err == '' and len(out) == 1 and out[0]['solutions'] == []
    assert out[0]['error'].startswith(
        "pixel (1280, 960) is outside the lens model's valid range")


@pytest.mark.parametrize('scale', [1e200, 1e-200, 1e-300, 3.0, 1e300])
def test_a_scaled_down_vector_gives_the_unit_vector_solution(monkeypatch, capsys, scale):
    """A "down" of any finite nonzero length is one direction: same poses, no warnings."""
    line = {'uv': [[700, 500], [500, 520]], 'K': K, 'points': [[0, 0, 0], [1, 0, 0]],
            'down': [0, 0.8, 0.6]}
    scaled = dict(line, down=[0, 0.8 * scale, 0.6 * scale])
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        status, out, err = _run(monkeypatch, capsys, [json.dumps(line), json.dumps(scaled)])
    assert status == 0 and err == '' and 'error' not in out[1], out[1]
    assert len(out[0]['solutions']) == len(out[1]['solutions']) >= 1
    for unit, other in zip(out[0]['solutions'], out[1]['solutions']):
        assert np.allclose(unit['R'], other['R'], atol=1e-12)
        assert np.allclose(unit['t'], other['t'], atol=1e-12)


def test_p2p_over_a_bag_refuses_emitters_beyond_the_stated_range(capsys, tmp_path):
    """The range, not 'one vertical line', for accelcal p2p --emitters 0 0 0 1e300 0 0."""
    status = main(['p2p', str(tmp_path / 'none.mcap'), '--emitters', '0', '0', '0', '1e300',
                   '0', '0', '-o', str(tmp_path / 'poses.csv')])
    err = capsys.readouterr().err
    assert status == 1 and 'within +-1,000,000 m' in err and 'vertical' not in err
