"""Bad recordings: missing/wrong/empty topics, damaged bags, odd stamps, missing metadata."""
import io
import os
import shutil

from accelcal_ros.cli import main
from accelcal_ros.errors import FileFormatError, InputError
from accelcal_ros.recording.bag import BagReader
from accelcal_ros.recording.progress import Progress
from accelcal_ros.recording.sim_bags import bag_path, FORMATS
from accelcal_ros.recording.streams import check_stamps, read_imu
from accelcal_ros.recording.writer import BagWriter
import numpy as np
import pytest

RATE_HZ = 100.0


def _samples(n=400):
    t = np.arange(n) / RATE_HZ
    accel = np.tile([0.0, 0.0, 9.81], (n, 1)) + 0.01 * np.sin(t)[:, None]
    return t, accel


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    """Write a small IMU bag in each format, with a second Imu topic and a PointCloud2 topic."""
    root = tmp_path_factory.mktemp('bad')
    t, accel = _samples()
    out = {}
    for fmt in FORMATS:
        path = bag_path(root, 'imu', fmt)
        with BagWriter(path, fmt) as writer:
            writer.add_topic('/imu/data_raw', 'sensor_msgs/Imu')
            writer.add_topic('/imu/other', 'sensor_msgs/Imu')
            writer.add_topic('/points', 'sensor_msgs/PointCloud2')
            writer.add_topic('/empty', 'sensor_msgs/Imu')
            for k, (ti, ai) in enumerate(zip(t, accel)):
                ns = 10**9 + int(round(ti * 1e9))
                writer.write('/imu/data_raw', ns, writer.imu_message(ns, ai, 'imu_link'))
                if k % 10 == 0:
                    writer.write('/imu/other', ns, writer.imu_message(ns, ai, 'other'))
        out[fmt] = path
    return out


@pytest.mark.parametrize('fmt', FORMATS)
def test_topic_selection_errors(bags, fmt):
    """Missing, wrong-type, ambiguous and empty topics name what the bag has."""
    with BagReader(bags[fmt]) as bag:
        with pytest.raises(InputError, match=r'no topic /imu/nope; it has: .*/imu/data_raw '
                                             r'\(sensor_msgs/Imu, 400 messages\)'):
            read_imu(bag, '/imu/nope')
        with pytest.raises(InputError, match='is sensor_msgs/PointCloud2, not sensor_msgs/Imu'):
            read_imu(bag, 'points')
        with pytest.raises(InputError, match=r'several sensor_msgs/Imu topics: .*/imu/other '
                                             r'\(sensor_msgs/Imu, 40 messages\).*--topic'):
            read_imu(bag, None)
        with pytest.raises(InputError, match='/empty .* is empty'):
            read_imu(bag, '/empty')
        assert len(read_imu(bag, 'imu/other').t) == 40  # leading slash optional


def test_cli_errors_are_one_line(bags, tmp_path, capsys):
    """The CLI turns the errors into one line and writes nothing."""
    out = tmp_path / 'c.yaml'
    assert main(['calibrate', str(bags['mcap']), '-o', str(out)]) != 0
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'choose one with --topic' in err and not out.exists()
    assert main(['calibrate', str(tmp_path / 'missing.bag'), '-o', str(out)]) != 0
    assert 'no such bag' in capsys.readouterr().err


@pytest.mark.parametrize('fmt', FORMATS)
@pytest.mark.parametrize('keep', (0.4, 0.9))
def test_truncated_bag_is_an_error(bags, fmt, keep, tmp_path):
    """A cut-short bag raises FileFormatError saying so; a partial read is never returned."""
    src = bags[fmt]
    if src.is_dir():
        data_file = next(p for p in src.iterdir() if p.suffix in ('.mcap', '.db3'))
        dst = tmp_path / src.name
        shutil.copytree(src, dst)
        target = dst / data_file.name
    else:
        dst = target = tmp_path / src.name
        shutil.copy(src, dst)
    data = target.read_bytes()
    target.write_bytes(data[:int(len(data) * keep)])
    with pytest.raises(FileFormatError) as info:
        with BagReader(dst) as bag:
            read_imu(bag, '/imu/data_raw')
    text = str(info.value)
    assert str(dst) in text
    assert ('cannot open bag' in text) or ('corrupt or truncated: read' in text)


def test_corrupt_chunk_says_how_far_it_read(bags, tmp_path):
    """Damage in the middle of a ROS 1 bag: the error counts the messages read before it."""
    dst = tmp_path / 'bad.bag'
    data = bytearray(bags['ros1'].read_bytes())
    mid = len(data) // 2
    data[mid:mid + 400] = b'\xab' * 400
    dst.write_bytes(bytes(data))
    with pytest.raises(FileFormatError, match=r'read \d+ of 4\d\d messages.*nothing is computed'):
        with BagReader(dst) as bag:
            read_imu(bag, '/imu/data_raw')


def test_directory_without_metadata(bags, tmp_path, capsys):
    """One storage file: read with a note; none or several: an error saying what to do."""
    one = tmp_path / 'one'
    shutil.copytree(bags['mcap'], one)
    os.remove(one / 'metadata.yaml')
    with BagReader(one) as bag:
        assert 'no metadata.yaml' in bag.notes[0]
        assert len(read_imu(bag, '/imu/data_raw').t) == 400
    (tmp_path / 'none').mkdir()
    with pytest.raises(FileFormatError, match='without metadata.yaml and without'):
        BagReader(tmp_path / 'none')
    shutil.copy(next(one.glob('*.mcap')), one / 'two.mcap')
    with pytest.raises(FileFormatError, match='several storage files'):
        BagReader(one)


def test_stamp_warnings(tmp_path):
    """Backwards steps, jumps and header/receive offsets are counted and the choice stated."""
    t, accel = _samples()
    header = t.copy()
    header[100], header[101] = header[101], header[100]   # one step back (header stamps)
    header[300:] += 2.0                                    # one jump
    path = tmp_path / 'odd'
    with BagWriter(path, 'mcap') as writer:
        writer.add_topic('/imu/data_raw', 'sensor_msgs/Imu')
        for ti, hi, ai in zip(t, header, accel):
            ns = 10**9 + int(round(hi * 1e9))
            writer.write('/imu/data_raw', 10**9 + int(round((ti + 3.0) * 1e9)),
                         writer.imu_message(ns, ai, 'imu_link'))
    with BagReader(path) as bag:
        imu = read_imu(bag, None)
    text = '\n'.join(imu.warnings)
    assert 'time goes backwards 1 times' in text and '1 time jumps' in text
    assert 'header stamps differ from the bag receive times by -3.0' in text
    assert 'using header stamps' in text
    assert np.all(np.diff(imu.t) > 0) and len(imu.t) == 400
    with BagReader(path, stamp='receive') as bag:
        imu = read_imu(bag, None)
    assert 'using receive times' in '\n'.join(imu.warnings)
    assert check_stamps('/x', np.zeros(3), np.arange(3.0), 'header') == []
    # images stamped alike (a driver that stamps once): said, where no sort drops them
    same = check_stamps('/cam', np.full(20, 5.0), 5.0 + 0.1 * np.arange(20), 'header',
                        repeats=True)
    assert any('19 of 20 messages repeat the previous time' in w for w in same), same
    assert not any('repeat' in w for w in check_stamps('/cam', np.full(20, 5.0), 5.0 + 0.1
                                                       * np.arange(20), 'header'))


def test_progress_bar_only_on_a_terminal(monkeypatch):
    """Nothing is drawn on a pipe; the bar is drawn when forced (as on a terminal)."""
    stream = io.StringIO()
    with Progress(10, 'reading', stream=stream, min_interval_s=0.0) as bar:
        bar.update(5)
    assert stream.getvalue() == ''
    monkeypatch.setenv('ACCELCAL_PROGRESS', '1')
    with Progress(10, 'reading', stream=stream, min_interval_s=0.0) as bar:
        bar.update(5)
    assert 'reading [' in stream.getvalue() and '100% 10/10' not in stream.getvalue()
    assert '50%' in stream.getvalue()


def test_an_imu_topic_that_reads_off_1_g_without_calibration_is_warned_about(tmp_path):
    """
    Warn when a bag's raw IMU topic drives the attitude with no ``--calibration``.

    p2p over the sample bag was 10 deg of yaw and 1.1 m off with status 0 and no word.
    """
    from accelcal_ros.recording.sim_bags import write_imu_bag
    from accelcal_ros.recording.streams import attitude_series
    from accelcal_ros.sensor.model import SensorModel

    t = np.arange(200) * 0.01
    for scale, warned in ((0.9, True), (1.0, False)):
        path = write_imu_bag(tmp_path / f'b{scale}', 'mcap', t,
                             np.tile([0.0, 0.0, 9.80665 * scale], (200, 1)))
        with BagReader(path) as bag:
            *_, warnings = attitude_series(bag, None, '/imu/data_raw')
            assert any('look uncalibrated (median |a| 0.900 g' in w for w in warnings) == warned
            *_, calibrated = attitude_series(bag, None, '/imu/data_raw',
                                             SensorModel.identity())
            assert not any('uncalibrated' in w for w in calibrated)
