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


def _save(path, t, rows, header='t,ax,ay,az'):
    with open(path, 'w') as handle:
        handle.write(header + '\n')
        for ti, row in zip(t, rows):
            handle.write(','.join(str(v) for v in (ti, *row)) + '\n')


def _one_error_line(capsys):
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    errors = [line for line in lines if not line.startswith('note:')]
    assert len(errors) == 1 and errors[0].startswith('accelcal: error:'), captured.err
    assert 'internal error' not in errors[0] and 'Warning' not in captured.err
    return errors[0]


def test_attitude_counts_skipped_samples_and_refuses_none_usable(tmp_path, capsys):
    """All 0,0,0 / 1e308 / NaN wrote 'wrote 0 rows', status 0; single bad rows uncounted."""
    import warnings

    t = np.arange(200) * 0.01
    rec, out = tmp_path / 'rec.csv', tmp_path / 'att.csv'
    for value in (0.0, 1e308, float('nan')):
        _save(rec, t, np.full((200, 3), value))
        with warnings.catch_warnings():
            warnings.simplefilter('error', RuntimeWarning)
            assert main(['attitude', str(rec), '-o', str(out)]) == 1
        assert 'no usable sample' in _one_error_line(capsys) and not out.exists()
    rows = np.tile([0.0, 0.0, 9.80665], (200, 1))
    rows[7] = 0.0
    rows[9, 1] = float('nan')
    _save(rec, t, rows)
    assert main(['attitude', str(rec), '-o', str(out)]) == 0
    summary = capsys.readouterr().out
    assert 'wrote 198 rows' in summary and '2 impossible sample(s) skipped' in summary
    assert main(['attitude', str(rec)]) == 0  # to stdout: the count goes to stderr
    assert 'note: 2 impossible sample(s) skipped' in capsys.readouterr().err


def test_absurd_or_disjoint_odometry_is_refused(tmp_path, capsys):
    """Odometry at 1e308 printed overflow warnings; one from t = 1e6 s claimed 'aided'."""
    import warnings

    t = np.arange(0.0, 20.0, 0.01)
    rec, odo, out = tmp_path / 'rec.csv', tmp_path / 'odo.csv', tmp_path / 'att.csv'
    _save(rec, t, np.tile([0.0, 0.0, 9.80665], (t.size, 1)))
    t_odo = np.arange(0.0, 20.0, 0.1)
    for v, rate, what in ((1e308, 0.0, 'odometry v'), (1.0, 1e308, 'odometry yaw_rate'),
                          (101.0, 0.0, 'beyond 100 m/s'), (1.0, -11.0, 'beyond 10 rad/s')):
        _save(odo, t_odo, [(v, rate)] * t_odo.size, 't,v,yaw_rate')
        with warnings.catch_warnings():
            warnings.simplefilter('error', RuntimeWarning)
            assert main(['attitude', str(rec), '--odometry', str(odo), '-o', str(out)]) == 1
        line = _one_error_line(capsys)
        assert what in line and 'odo.csv:2:' in line, line
    _save(odo, t_odo + 1e6, [(1.0, 0.1)] * t_odo.size, 't,v,yaw_rate')
    assert main(['attitude', str(rec), '--odometry', str(odo), '-o', str(out)]) == 1
    assert 'does not overlap the recording' in _one_error_line(capsys) and not out.exists()
    _save(odo, t_odo + 10.0, [(1.0, 0.0)] * t_odo.size, 't,v,yaw_rate')
    assert main(['attitude', str(rec), '--odometry', str(odo), '-o', str(out)]) == 0
    assert 'odometry-aided (50% of the samples)' in capsys.readouterr().err
