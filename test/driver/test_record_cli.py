"""``accelcal record`` on the simulated sensor (no ROS graph)."""
from accelcal_ros.cli import main
from accelcal_ros.sensor.recording import load_recording
import numpy as np


def test_record_sim_writes_a_loadable_recording(tmp_path, capsys):
    """The recording has the requested length and +g on z while level."""
    out = tmp_path / 'rec.csv'
    assert main(['record', '-o', str(out), '--duration', '2', '--rate', '50',
                 '--poses-deg', '0', '0', '--dwell', '10']) == 0
    t, accel = load_recording(out)
    assert len(t) == 100 and np.allclose(np.diff(t), 0.02)
    assert accel[:, 2].mean() > 8.0
    assert 'wrote 100 samples' in capsys.readouterr().out


def test_record_rejects_bad_duration(tmp_path, capsys):
    """A non-positive duration is a one-line error with exit status 2; nothing written."""
    out = tmp_path / 'rec.csv'
    assert main(['record', '-o', str(out), '--duration', '0']) == 2
    assert '--duration' in capsys.readouterr().err
    assert not out.exists()


def _one_error_line(capsys):
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('accelcal: error:'), captured.err
    return lines[0]


def test_a_recording_of_no_sample_is_refused_before_recording(tmp_path, capsys):
    """--duration x --rate under one sample (CSV or bag): one line, status 1, nothing written."""
    out, bag = tmp_path / 'rec.csv', tmp_path / 'bag'
    for argv in (['-o', str(out), '--duration', '0.001'],
                 ['-o', str(out), '--duration', '0.05', '--rate', '6.25'],
                 ['--bag', str(bag), '--duration', '0.001'],
                 ['-o', str(out), '--sim-bus', 'spi', '--duration', '0.001'],
                 ['-o', str(out), '--duration', '0.1', '--rate', '6.25']):   # 0.625 periods
        assert main(['record', *argv]) == 1, argv
        line = _one_error_line(capsys)
        assert 'gives no sample' in line and 'needs at least' in line
    assert not out.exists() and not bag.exists()
    assert main(['record', '-o', str(out), '--duration', '0.16', '--rate', '6.25']) == 0
    assert len(load_recording(out)[0]) == 1


def test_a_rate_the_adxl345_has_not_is_a_usage_error_on_every_backend(tmp_path, capsys):
    """--rate 7 / 6.24 / 0.001 was recorded by the sample-level sim: now status 2 at parse."""
    out = tmp_path / 'rec.csv'
    for rate in ('7', '6.24', '0.001'):
        for extra in ([], ['--sim-bus', 'i2c']):
            assert main(['record', '-o', str(out), '--rate', rate, *extra]) == 2
            assert '--rate' in _one_error_line(capsys)
    assert not out.exists()


def test_bag_frame_id_is_checked_like_the_nodes(tmp_path, capsys):
    """--frame-id '/bad frame' was written into the bag; refused as frame_tree refuses it."""
    from accelcal_ros.driver.params import DRIVER_PARAMS

    bag = tmp_path / 'bag'
    for frame in ('/bad frame', 'bad frame', '/imu_link', '9imu'):
        assert main(['record', '--bag', str(bag), '--duration', '0.1', '--frame-id',
                     frame]) == 1
        assert '--frame-id' in _one_error_line(capsys)
    assert not bag.exists()
    spec = next(s for s in DRIVER_PARAMS if s.name == 'frame_id')  # the node's parameter
    assert spec.check('/bad frame')[1] and spec.check('')[1].endswith('must not be empty')
    assert not spec.check('imu_top')[1]
