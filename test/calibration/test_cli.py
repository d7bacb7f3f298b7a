"""``accelcal calibrate / apply / attitude / plot-calibration`` on simulated recordings."""
import os

from accelcal_ros.calibration.coverage import recommended_directions, roll_pitch_deg_of
from accelcal_ros.cli import main
from accelcal_ros.driver.sim_sensor import SimulatedAdxl345
from accelcal_ros.sensor.calibration_file import load_sensor_model
from accelcal_ros.sensor.recording import save_recording
import numpy as np
import pytest

pytestmark = pytest.mark.filterwarnings('ignore:Gimbal lock')
G = 9.80665


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    poses = roll_pitch_deg_of(recommended_directions(12))
    sim = SimulatedAdxl345(poses_deg=poses, dwell_s=1.5, move_s=0.7, seed=5)
    t = np.arange(0.0, sim.period_s * 12, 0.01)
    raw = sim.read(t)
    path = tmp_path_factory.mktemp('rec') / 'rec.csv'
    save_recording(path, t, raw * G)
    return path, sim, t, raw


def test_calibrate_apply_attitude_plot(tmp_path, recording, capsys):
    path, sim, t, raw = recording
    calib = tmp_path / 'calib.yaml'
    plot = tmp_path / 'calib.png'
    assert main(['calibrate', str(path), '-o', str(calib), '--plot', str(plot)]) == 0
    out = capsys.readouterr().out
    assert 'full model from 12 positions' in out and 'predicted roll/pitch' in out
    model = load_sensor_model(calib)
    np.testing.assert_allclose(model.scale, sim.truth.scale, atol=1e-3)
    np.testing.assert_allclose(model.bias, sim.truth.bias, atol=1e-3)
    assert plot.read_bytes()[:4] == b'\x89PNG'

    corrected = tmp_path / 'corrected.csv'
    assert main(['apply', str(path), '--calibration', str(calib), '-o', str(corrected)]) == 0
    data = np.loadtxt(corrected, delimiter=',', skiprows=1)
    assert data.shape == (len(t), 4)
    still = sim.pose_index(t) >= 0
    norms = np.linalg.norm(data[still, 1:], axis=1) / G
    assert abs(np.mean(norms) - 1.0) < 1e-3

    out_csv = tmp_path / 'att.csv'
    assert main(['attitude', str(path), '--calibration', str(calib), '-o',
                 str(out_csv)]) == 0
    att = np.loadtxt(out_csv, delimiter=',', skiprows=1)
    roll, pitch = sim.attitude_at(t)
    sel = still & (np.abs(pitch) < np.radians(80))
    roll_err = np.angle(np.exp(1j * (np.radians(att[sel, 1]) - roll[sel])))
    # Single samples: noise ~0.2-0.3 deg per sample; the mean error is the calibration's.
    assert abs(np.degrees(np.mean(np.radians(att[sel, 2]) - pitch[sel]))) < 0.05
    assert np.degrees(np.sqrt(np.mean(roll_err ** 2))) < 0.6
    assert np.all(np.isfinite(att))
    assert 'does not fit' not in capsys.readouterr().err


def test_a_mismatched_calibration_is_reported(tmp_path, recording, capsys):
    """Another sensor's calibration (paper A's K = 100 set) on this recording: a warning."""
    from accelcal_ros.sensor.calibration_file import save_calibration
    from accelcal_ros.sensor.model import paper_a_model

    path, sim, t, raw = recording
    other = paper_a_model(100)

    class Result:   # the fields save_calibration writes
        model, sensor_model, positions, dropped = 'diagonal', other, 12, []
        scale_std = bias_std = misalignment_std = np.zeros(3)
        residual_rms_g, holdout_rms_g, condition_number = 0.001, None, 10.0
        predicted_tilt_error_deg, captures_g, residuals_g = 0.1, [], []

    calib = tmp_path / 'other.yaml'
    save_calibration(calib, Result())
    out = tmp_path / 'corrected.csv'
    assert main(['apply', str(path), '--calibration', str(calib), '-o', str(out)]) == 0
    err = capsys.readouterr().err
    assert 'does not fit' in err and 'this sensor' in err
    assert main(['attitude', str(path), '--calibration', str(calib)]) == 0
    assert 'does not fit' in capsys.readouterr().err


def test_plot_calibration_command(tmp_path, recording):
    path, *_ = recording
    calib = tmp_path / 'calib.yaml'
    assert main(['calibrate', str(path), '-o', str(calib)]) == 0
    png = tmp_path / 'plot.png'
    assert main(['plot-calibration', str(calib), '-o', str(png)]) == 0
    assert png.stat().st_size > 10000


def test_bad_inputs_exit_2_and_write_nothing(tmp_path, recording, capsys):
    path, sim, t, raw = recording
    out = tmp_path / 'calib.yaml'
    # Too few positions: the first three dwells only.
    short = tmp_path / 'short.csv'
    n = int(sim.period_s * 3 / 0.01)
    save_recording(short, t[:n], raw[:n] * G)
    assert main(['calibrate', str(short), '-o', str(out)]) == 1
    err = capsys.readouterr().err
    assert 'too few' in err and not out.exists()
    assert 'finish' not in err and 'run accelcal calibrate again' in err  # not a service
    # Truncated recording.
    truncated = tmp_path / 'trunc.csv'
    truncated.write_text(path.read_text()[:5000].rsplit(',', 1)[0])
    assert main(['calibrate', str(truncated), '-o', str(out)]) == 1
    assert 'trunc.csv' in capsys.readouterr().err and not out.exists()
    # Missing or broken calibration file.
    bad = tmp_path / 'bad.yaml'
    bad.write_text('model: full\nscale: [1, 1]\nbias: [0, 0, 0]\n')
    for calib in (tmp_path / 'missing.yaml', bad):
        result = tmp_path / 'corr.csv'
        assert main(['apply', str(path), '--calibration', str(calib), '-o', str(result)]) == 1
        assert str(calib) in capsys.readouterr().err and not result.exists()
    assert not [f for f in os.listdir(tmp_path) if f.startswith('.')]


def test_nan_and_saturated_samples_in_a_recording_are_skipped(tmp_path, recording, capsys):
    path, sim, t, raw = recording
    raw = raw.copy()
    raw[7::150] = np.nan
    raw[30::700, 1] = 16.0
    noisy = tmp_path / 'nan.csv'
    save_recording(noisy, t, raw * G)
    out = tmp_path / 'calib.yaml'
    assert main(['calibrate', str(noisy), '-o', str(out)]) == 0
    assert 'samples rejected' in capsys.readouterr().out
    np.testing.assert_allclose(load_sensor_model(out).bias, sim.truth.bias, atol=2e-3)


@pytest.mark.parametrize('order', ['reversed', 'constant'])
def test_times_that_do_not_increase_are_refused_with_their_line(tmp_path, recording, capsys,
                                                                order):
    """Reversed rows or every t = 0: calibrate and attitude refuse them, writing nothing."""
    path, sim, t, raw = recording
    bad = tmp_path / 'bad.csv'
    save_recording(bad, t[::-1] if order == 'reversed' else np.zeros_like(t), raw * G)
    calib, att = tmp_path / 'calib.yaml', tmp_path / 'att.csv'
    for argv in (['calibrate', str(bad), '-o', str(calib)],
                 ['attitude', str(bad), '-o', str(att)]):
        assert main(argv) == 1
        errors = [line for line in capsys.readouterr().err.splitlines() if 'error' in line]
        assert len(errors) == 1 and f'{bad}:3: column t must increase strictly' in errors[0]
    assert not calib.exists() and not att.exists()


def test_a_directory_for_a_file_output_is_refused_before_any_work(tmp_path, recording,
                                                                  capsys):
    """`calibrate -o c.yaml --plot DIR`, `-o DIR`: refused up front; c.yaml never written."""
    path, *_ = recording
    folder = tmp_path / 'DIR'
    folder.mkdir()
    calib = tmp_path / 'c.yaml'
    for argv in (['calibrate', str(path), '-o', str(calib), '--plot', str(folder)],
                 ['calibrate', str(path), '-o', str(folder)],
                 ['attitude', str(path), '-o', str(folder)],
                 ['plot-calibration', str(calib), '-o', str(folder)]):
        assert main(argv) == 1
        out, err = capsys.readouterr()
        assert err.count('\n') == 1 and 'is a directory' in err and out == ''  # nothing ran
    assert not calib.exists() and os.listdir(folder) == []


def test_outputs_it_cannot_write_under_their_name_are_refused(tmp_path, recording, capsys):
    """A plot is a PNG; a CSV recording is applied into a CSV, never under a bag's name."""
    path, *_ = recording
    calib = tmp_path / 'calib.yaml'
    assert main(['calibrate', str(path), '-o', str(calib)]) == 0
    capsys.readouterr()
    plot, other = tmp_path / 'p.txt', tmp_path / 'c2.yaml'
    for argv in (['plot-calibration', str(calib), '-o', str(plot)],
                 ['calibrate', str(path), '-o', str(other), '--plot', str(plot)]):
        assert main(argv) == 1
        err = capsys.readouterr().err
        assert err.count('\n') == 1 and "p.txt' must end with .png" in err
    assert not plot.exists() and not other.exists()
    for name in ('ap.mcap', 'ap.db3', 'ap.bag', 'ap_dir'):
        assert main(['apply', str(path), '--calibration', str(calib), '-o',
                     str(tmp_path / name)]) == 1
        err = capsys.readouterr().err
        assert err.count('\n') == 1 and 'CSV recording' in err and 'NAME.csv' in err
        assert not (tmp_path / name).exists()
    out = tmp_path / 'ap.csv'
    assert main(['apply', str(path), '--calibration', str(calib), '--corrected-topic', '/x',
                 '-o', str(out)]) == 1
    assert 'applies to a bag output' in capsys.readouterr().err and not out.exists()


def _one_error_line(capsys):
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('accelcal: error:'), captured.err
    assert 'internal error' not in lines[0]
    return lines[0]


def test_apply_skips_and_counts_non_finite_samples(tmp_path, recording, capsys):
    """One inf in ax wrote 'inf,nan,nan' with a RuntimeWarning; all NaN wrote NaN rows."""
    import warnings

    path, sim, t, raw = recording
    calib = tmp_path / 'calib.yaml'
    assert main(['calibrate', str(path), '-o', str(calib)]) == 0
    capsys.readouterr()
    bad = raw[:50].copy()
    bad[5, 0] = np.inf
    bad[9, 2] = np.nan
    bad[11, 1] = 1e300
    rec, out = tmp_path / 'bad.csv', tmp_path / 'out.csv'
    save_recording(rec, t[:50], bad * G)
    with warnings.catch_warnings():
        warnings.simplefilter('error', RuntimeWarning)
        assert main(['apply', str(rec), '--calibration', str(calib), '-o', str(out)]) == 0
    summary = capsys.readouterr().out
    assert 'wrote 47 calibrated samples' in summary and '3 sample(s) with a NaN' in summary
    written = np.loadtxt(out, delimiter=',', skiprows=1)
    assert written.shape == (47, 4) and np.all(np.isfinite(written))
    assert not np.isin(t[[5, 9, 11]].round(6), written[:, 0]).any()
    for value in (np.nan, np.inf, 1e308):
        save_recording(rec, t[:50], np.full((50, 3), value))
        out.unlink(missing_ok=True)
        with warnings.catch_warnings():
            warnings.simplefilter('error', RuntimeWarning)
            assert main(['apply', str(rec), '--calibration', str(calib), '-o', str(out)]) == 1
        assert 'no usable sample' in _one_error_line(capsys) and not out.exists()


def test_calibrate_on_all_zero_samples_is_one_line_without_warning(tmp_path, capsys):
    """A still dwell reading 0,0,0 was captured with a NaN direction (RuntimeWarning)."""
    import warnings

    rec, out = tmp_path / 'zero.csv', tmp_path / 'c.yaml'
    t = np.arange(500) * 0.01
    save_recording(rec, t, np.zeros((500, 3)))
    with warnings.catch_warnings():
        warnings.simplefilter('error', RuntimeWarning)
        assert main(['calibrate', str(rec), '-o', str(out)]) == 1
    captured = capsys.readouterr()
    assert 'no gravity direction' in captured.out and '0 positions' in captured.err
    assert captured.err.count('\n') == 1 and not out.exists()


def test_apply_to_a_bag_skips_and_counts_non_finite_messages(tmp_path, recording, capsys):
    """A NaN/inf Imu message is not 'calibrated' into the output bag; all bad: nothing."""
    from accelcal_ros.recording.bag import BagReader
    from accelcal_ros.recording.writer import BagWriter

    path, sim, t, raw = recording
    calib = tmp_path / 'calib.yaml'
    assert main(['calibrate', str(path), '-o', str(calib)]) == 0

    def bag_of(name, rows):
        with BagWriter(tmp_path / name, 'mcap') as writer:
            writer.add_topic('/imu/data_raw', 'sensor_msgs/Imu')
            for k, row in enumerate(rows):
                ns = 10**9 + k * 10**7
                writer.write('/imu/data_raw', ns,
                             writer.imu_message(ns, row, 'imu_link', topic='/imu/data_raw'))
        return str(tmp_path / name)

    rows = raw[:20] * G
    rows[3, 0] = np.inf
    rows[4, 2] = np.nan
    capsys.readouterr()
    assert main(['apply', bag_of('in', rows), '--calibration', str(calib), '-o',
                 str(tmp_path / 'out')]) == 0
    assert '18 calibrated' in capsys.readouterr().out
    with BagReader(str(tmp_path / 'out')) as bag:
        accel = [(m.msg.linear_acceleration.x, m.msg.linear_acceleration.y)
                 for m in bag.messages(['/imu/data_raw'], decode=['/imu/data_raw'])]
    assert len(accel) == 18 and np.all(np.isfinite(accel))
    assert main(['apply', bag_of('nan', np.full((5, 3), np.nan)), '--calibration', str(calib),
                 '-o', str(tmp_path / 'out2')]) == 1
    assert 'no usable' in _one_error_line(capsys) and not (tmp_path / 'out2').exists()
    assert main(['apply', bag_of('empty', np.zeros((0, 3))), '--calibration', str(calib),
                 '-o', str(tmp_path / 'out3')]) == 1
    assert 'is empty (0 messages)' in _one_error_line(capsys)   # refused before 'no usable'
    assert not (tmp_path / 'out3').exists()
