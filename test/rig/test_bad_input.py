"""``accelcal rig-calibrate`` on bad input: one clear line, a failure status, nothing written."""
import os
import shutil

from accelcal_ros.cli import main
from accelcal_ros.rig.dataset import pose_gravity
from accelcal_ros.rig.render import (default_truth, imu_samples, plan_poses, write_dataset,
                                     write_imu_csv)
from accelcal_ros.sensor.model import SensorModel
import cv2
import numpy as np
import pytest

TRUTH = default_truth()


@pytest.fixture(scope='module')
def small(tmp_path_factory):
    """Three rendered poses (enough to fail in each way, not to calibrate)."""
    directory = tmp_path_factory.mktemp('small_capture')
    write_dataset(str(directory), TRUTH, plan_poses(TRUTH, 3))
    return directory


def _copy(small, tmp_path):
    target = tmp_path / 'capture'
    shutil.copytree(small, target)
    return target


def _run(directory, tmp_path, *extra, board='11x8'):
    out = tmp_path / 'rig.yaml'
    status = main(['rig-calibrate', str(directory), '--board', board, '--square-m', '0.025',
                   '-o', str(out)] + list(extra))
    assert not out.exists()
    return status


def test_wrong_board_size_says_what_was_seen(small, tmp_path, capsys):
    """A 9x6 asked for, an 11x8 in the images."""
    assert _run(small, tmp_path, board='9x6') != 0
    err = capsys.readouterr().err
    assert 'no 9x6 board found in any image of poses pose00, pose01, pose02' in err
    assert 'shows a 11x8 board' in err and '--board' in err


def test_no_board_anywhere_names_the_poses(tmp_path, capsys):
    """Blank images: the error lists the poses."""
    for pose in ('pose00', 'pose01'):
        folder = tmp_path / 'blank' / pose
        folder.mkdir(parents=True)
        cv2.imwrite(str(folder / 'cam0.png'), np.full((600, 800), 110, np.uint8))
        write_imu_csv(str(folder / 'imu.csv'), {'t': np.arange(3) * 0.5,
                                                'a': np.tile([0.0, 0.0, 9.8], (3, 1))})
    assert _run(tmp_path / 'blank', tmp_path) != 0
    err = capsys.readouterr().err
    assert 'no 11x8 board found in any image of poses pose00, pose01' in err


def test_missing_imu_csv(small, tmp_path, capsys):
    """A pose without its accelerometer log is named."""
    capture = _copy(small, tmp_path)
    os.remove(capture / 'pose01' / 'imu.csv')
    assert _run(capture, tmp_path) != 0
    err = capsys.readouterr().err
    assert 'pose01' in err and 'imu.csv' in err and 'missing' in err


def test_inconsistent_image_sizes(small, tmp_path, capsys):
    """One camera with two resolutions."""
    capture = _copy(small, tmp_path)
    cv2.imwrite(str(capture / 'pose02' / 'cam1.png'), np.full((480, 640), 110, np.uint8))
    assert _run(capture, tmp_path) != 0
    err = capsys.readouterr().err
    assert 'camera cam1: images of different sizes' in err and '640x480' in err


def test_intrinsics_file_of_the_wrong_size(small, tmp_path, capsys):
    """camera_info for 640x480 given for an 800x600 camera."""
    path = tmp_path / 'cam0.yaml'
    path.write_text('image_width: 640\nimage_height: 480\ncamera_name: cam0\n'
                    'camera_matrix: {rows: 3, cols: 3, data: [400, 0, 320, 0, 400, 240, 0, 0, '
                    '1]}\ndistortion_model: plumb_bob\n'
                    'distortion_coefficients: {rows: 1, cols: 5, data: [0, 0, 0, 0, 0]}\n')
    assert _run(small, tmp_path, '--intrinsics', str(path)) != 0
    err = capsys.readouterr().err
    assert 'is for 640x480 images but camera cam0 took 800x600' in err


def test_unknown_reference_and_too_few_views(small, tmp_path, capsys):
    """--reference must name a camera; three poses are too few for the intrinsics."""
    assert _run(small, tmp_path, '--reference', 'cam9') != 0
    assert "--reference 'cam9' is not a camera" in capsys.readouterr().err
    assert _run(small, tmp_path) != 0
    assert 'need at least 4' in capsys.readouterr().err


def test_accelerometer_calibration_is_applied(tmp_path):
    """Raw readings through a sensor model come back as the true gravity direction."""
    pose = plan_poses(TRUTH, 1)[0]
    samples = imu_samples(TRUTH, pose, np.random.default_rng(1), noise_m_s2=0.0)
    model = SensorModel(np.array([0.95, 1.03, 0.98]), np.array([0.02, -0.03, 0.05]),
                        np.zeros(3))
    raw = model.distort(samples['a'] / 9.80665) * 9.80665
    path = str(tmp_path / 'imu.csv')
    write_imu_csv(path, {'t': samples['t'], 'a': raw})
    corrected, why = pose_gravity(path, model)
    assert not why
    assert np.allclose(corrected, 9.80665 * pose.specific_force, atol=1e-3)
    uncorrected, _ = pose_gravity(path)
    assert not np.allclose(uncorrected, corrected, atol=0.05)


@pytest.mark.parametrize('reading, words', [
    ([0.0, 0.0, 0.0], 'reads 0.000 g (uncalibrated), not gravity'),
    ([0.0, 0.0, 4.9], 'reads 0.500 g (uncalibrated), not gravity'),
    ([0.0, 1e300, 0.0], 'corrupt accelerometer log: sample 1 reads 1e+300 m/s^2'),
])
def test_a_still_log_that_is_not_gravity_drops_the_pose(tmp_path, reading, words):
    """A zero, half-g or 1e300 still log had its 'direction' pull imu_to_camera away."""
    import warnings

    path = str(tmp_path / 'imu.csv')
    write_imu_csv(path, {'t': np.arange(100) * 0.01, 'a': np.tile(reading, (100, 1))})
    with warnings.catch_warnings():
        warnings.simplefilter('error', RuntimeWarning)
        value, why = pose_gravity(path)
    assert value is None and words in why, why
    # with a fitted calibration the band is 0.9..1.1 g: 0.85 g is another sensor's calibration
    write_imu_csv(path, {'t': np.arange(100) * 0.01, 'a': np.tile([0, 0, 0.85 * 9.80665],
                                                                  (100, 1))})
    assert pose_gravity(path)[0] is not None            # raw: within 0.7..1.3 g
    model = SensorModel(np.array([1.01, 1.0, 1.0]), np.zeros(3), np.zeros(3))
    value, why = pose_gravity(path, model)
    assert value is None and 'after the calibration' in why and 'another sensor' in why


def test_too_few_gravity_poses_names_why_they_were_dropped(small, tmp_path, capsys):
    """Every pose's log reads 0 g: the error says so (was a NaN mounting or a bare count)."""
    from accelcal_ros.camera import CameraModel
    from accelcal_ros.camera.camera_info import save_camera_info

    capture = _copy(small, tmp_path)
    files = []
    for name, size, k, d in zip(TRUTH.names, TRUTH.sizes, TRUTH.K, TRUTH.D):
        files.append(str(tmp_path / f'{name}.yaml'))
        save_camera_info(files[-1], name, CameraModel(size[0], size[1], k, d))
    for pose in ('pose00', 'pose01', 'pose02'):
        for other in TRUTH.names[1:]:   # one camera: no extrinsics needed
            os.remove(capture / pose / f'{other}.png')
        write_imu_csv(str(capture / pose / 'imu.csv'),
                      {'t': np.arange(100) * 0.01, 'a': np.zeros((100, 3))})
    assert _run(capture, tmp_path, '--intrinsics', files[0]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'needs at least 2 poses' in err and 'got 0' in err, err
    assert '3 poses dropped: pose00: the accelerometer reads 0.000 g' in err
    assert 'RuntimeWarning' not in err and 'nan' not in err.lower()


def test_outputs_are_checked_before_any_work(small, tmp_path, capsys):
    """A derived output that cannot be written is refused first, not after calibrating."""
    (tmp_path / 'rig_report.yaml').mkdir()
    assert _run(small, tmp_path) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'rig_report.yaml' in err and 'need at least 4' not in err
    os.rmdir(tmp_path / 'rig_report.yaml')
    out = tmp_path / 'rig_cam0_camera_info.yaml'
    os.symlink(str(small / 'pose00' / 'imu.csv'), out)   # a derived output onto an input
    assert _run(small, tmp_path) == 1
    assert 'a directory the command reads' in capsys.readouterr().err
    assert (small / 'pose00' / 'imu.csv').read_text().startswith('t')
    os.remove(out)
    assert _run(small, tmp_path, '--export', str(tmp_path / 'x')) == 1
    assert '--export is for a bag' in capsys.readouterr().err
    assert not (tmp_path / 'x').exists()
