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
