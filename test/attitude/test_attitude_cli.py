"""``accelcal study motion`` and ``accelcal attitude`` with gyro columns and odometry."""
from accelcal_ros.cli import main
from accelcal_ros.sensor.drive_sim import simulate_drive
import numpy as np


def _read(path):
    lines = path.read_text().splitlines()
    return lines[0], np.array([[float(v) for v in line.split(',')] for line in lines[1:]])


def test_study_writes_a_drive_that_attitude_reads_with_each_aid(tmp_path, capsys):
    drive_csv, odo_csv = tmp_path / 'drive.csv', tmp_path / 'odo.csv'
    assert main(['study', 'motion', '--no-anchors', '--drive-out', str(drive_csv),
                 '--odometry-out', str(odo_csv)]) == 0
    out = capsys.readouterr().out
    assert '+ gyro + odometry' in out and 'Target + odometry' in out
    truth = simulate_drive(rate_hz=100.0, seed=0)
    errors = {}
    for name, extra in (('accel', ['--no-gyro']), ('gyro', []),
                        ('both', ['--odometry', str(odo_csv), '--lever-arm', '1.0', '0.3',
                                  '0.8'])):
        result = tmp_path / f'{name}.csv'
        assert main(['attitude', str(drive_csv), '-o', str(result)] + extra) == 0
        header, table = _read(result)
        assert header == 't,roll_deg,pitch_deg,roll_std_deg,pitch_std_deg,accelerating'
        keep = table[:, 0] > 2.0
        roll_err = np.abs(table[keep, 1] - np.degrees(truth.roll[keep]))
        pitch_err = np.abs(table[keep, 2] - np.degrees(truth.pitch[keep]))
        errors[name] = np.percentile(np.maximum(roll_err, pitch_err), 95)
    assert errors['accel'] > 10.0
    assert errors['gyro'] < 1.0
    assert errors['both'] < 0.5


def test_bad_gyro_columns_and_backwards_odometry_are_one_line(tmp_path, capsys):
    rec = tmp_path / 'rec.csv'
    rec.write_text('t,ax,ay,az,gx\n0,0,0,9.8,0\n0.01,0,0,9.8,0\n')
    assert main(['attitude', str(rec)]) == 1
    assert 'give all of gx,gy,gz' in capsys.readouterr().err
    rec.write_text('t,ax,ay,az\n0,0,0,9.8\n0.01,0,0,9.8\n')
    odo = tmp_path / 'odo.csv'
    odo.write_text('t,v,yaw_rate\n0,1,0\n1,1,0\n0.5,1,0\n')
    assert main(['attitude', str(rec), '--odometry', str(odo)]) == 1
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if line.startswith('accelcal: error')]
    assert len(errors) == 1 and 'odometry running backwards in time' in errors[0]
    assert 'Traceback' not in err
