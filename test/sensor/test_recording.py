"""Replay recordings: round trip, timing, and malformed or truncated files."""
from accelcal_ros.driver.sources import ReplaySource
from accelcal_ros.errors import FileFormatError
from accelcal_ros.sensor.recording import load_recording, save_recording
import numpy as np
import pytest


def test_round_trip_and_as_fast_as_possible(tmp_path):
    """A saved recording loads back; full-speed replay returns everything in chunks."""
    path = tmp_path / 'rec.csv'
    t = np.arange(1200) * 0.01
    accel = np.tile([0.1, -0.2, 9.8], (1200, 1))
    save_recording(path, t, accel)
    t2, a2 = load_recording(path)
    assert np.allclose(t2, t) and np.allclose(a2, accel)
    clock = iter(np.arange(0, 100, 0.001)).__next__
    source = ReplaySource(path, realtime=False, clock=clock, chunk=500)
    source.start()
    sizes = [len(source.poll()) for _ in range(4)]
    assert sizes == [500, 500, 200, 0] and source.stats.finished
    assert source.samples_g[0] == pytest.approx(accel[0] / 9.80665)


def test_realtime_replay_keeps_recorded_spacing(tmp_path):
    """Real-time replay releases the samples whose recorded time has come."""
    path = tmp_path / 'rec.csv'
    save_recording(path, 5.0 + np.arange(10) * 0.1, np.zeros((10, 3)))
    now = [0.0]
    source = ReplaySource(path, realtime=True, clock=lambda: now[0])
    source.start()
    now[0] = 0.25
    batch = source.poll()
    assert len(batch) == 3 and batch.stamps == pytest.approx([0.0, 0.1, 0.2])
    assert source.next_poll_time() == pytest.approx(0.3)


@pytest.mark.parametrize('text, line, message', [
    ('t,ax,ay,az\n0,0,0,9.8\n0.01,0,0,9.8\n0.02,0,0', 4, 'expected 4 fields'),
    ('t,ax,ay\n0,0,0\n', 1, 'header lacks'),
    ('t,ax,ay,az\n0,0,0,9.8\n0.01,0,x,9.8\n', 3, 'non-numeric'),
    ('t,ax,ay,az\n0,0,0,9.8\n0.01,nan,0,9.8\n', 3, 'NaN'),
    ('t,ax,ay,az\n0,0,0,9.8\n0,0,0,9.8\n', 3, 'increase'),
    ('', 1, 'empty file'),
    ('t,ax,ay,az\n', 2, 'no samples'),
])
def test_bad_files_name_the_line(tmp_path, text, line, message):
    """Malformed or truncated recordings: FileFormatError with file, line and reason."""
    path = tmp_path / 'bad.csv'
    path.write_text(text)
    with pytest.raises(FileFormatError, match=message) as info:
        load_recording(path)
    assert info.value.line == line and str(path) in str(info.value)


def test_missing_file(tmp_path):
    """A missing recording is a clear error."""
    with pytest.raises(FileFormatError, match='not found'):
        load_recording(tmp_path / 'nope.csv')


@pytest.mark.parametrize('finite', [True, False])
@pytest.mark.parametrize('text, line', [
    ('t,ax,ay,az\n0.02,0,0,9.8\n0.01,0,0,9.8\n0,0,0,9.8\n', 3),      # reversed rows
    ('t,ax,ay,az\n0,0,0,9.8\n0,0,0,9.8\n0,0,0,9.8\n', 3),            # every t = 0
    ('t,ax,ay,az,gx,gy,gz\n0,0,0,9.8,0,0,0\n1,0,0,9.8,0,0,0\n0.5,0,0,9.8,0,0,0\n', 4),
    ('t,ax,ay,az\nnan,0,0,9.8\n0.01,0,0,9.8\n', 2),                  # a NaN time
])
def test_times_that_do_not_increase_are_refused_at_their_line(tmp_path, text, line, finite):
    """read_recording (calibrate/apply/attitude, NaN samples kept or not) refuses bad t."""
    from accelcal_ros.sensor.recording import read_recording

    path = tmp_path / 'rec.csv'
    path.write_text(text)
    with pytest.raises(FileFormatError) as info:
        read_recording(path, finite=finite)
    message = str(info.value)
    assert info.value.line == line and ('column t' in message or 'NaN' in message)


def test_read_recording_keeps_nan_samples_and_gyro(tmp_path):
    """finite=False keeps a NaN sample (calibrate skips it); gyro columns come all or none."""
    from accelcal_ros.sensor.recording import read_recording

    path = tmp_path / 'rec.csv'
    path.write_text('t,ax,ay,az,gx,gy,gz\n0,nan,0,9.8,0.1,0,0\n0.01,0,0,9.8,0,0,0.2\n')
    recording = read_recording(path, finite=False)
    assert np.isnan(recording.accel[0, 0]) and recording.gyro[1, 2] == 0.2
    path.write_text('t,ax,ay,az,gx\n0,0,0,9.8,0\n')
    with pytest.raises(FileFormatError, match='give all of gx,gy,gz'):
        read_recording(path)


def test_a_recording_in_g_is_refused_with_the_unit(tmp_path):
    """
    Refuse ``t,ax,ay,az`` in g (median |a| near 1), naming the unit.

    Read as m/s^2 it was a sensor in free fall (calibrate: "0 positions, sensor moving";
    attitude skipped 99 % with status 0).
    """
    rng = np.random.default_rng(1)
    t = np.arange(500) * 0.01
    down = rng.normal(size=(500, 3)) * 0.05 + [0.0, 0.0, 1.0]
    save_recording(tmp_path / 'g.csv', t, down)
    with pytest.raises(FileFormatError, match=r'look like g \(median \|a\| (0\.99|1\.0)'):
        load_recording(str(tmp_path / 'g.csv'))
    save_recording(tmp_path / 'ms2.csv', t, down * 9.80665)
    assert load_recording(str(tmp_path / 'ms2.csv'))[1].shape == (500, 3)
