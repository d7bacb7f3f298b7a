"""
Special files: no reader follows a path into a device, FIFO or socket; every read is bounded.

The writer replaces only a regular file (or nothing), keeps ``.bak`` by a hard link (the
old file's inode, never a copy), and no command writes into a file or directory it reads
(a bag is a directory). Each case checks the exit status or error, the message, a time
bound (a hang fails the case through SIGALRM) and that the device nodes and inputs are
left as they were. ``/dev/null``, ``/dev/zero`` and ``/dev/full`` are only ever read or
offered as a target that must be refused before anything is written.
"""
import contextlib
import os
import signal
import socket
import stat
import threading

from accelcal_ros import filecheck, fileio, textformats
from accelcal_ros.errors import AccelcalError, FileFormatError, FileWriteError, InputError
import numpy as np
import pytest

LIMIT_S = 20.0  # a refusal is immediate; this only turns a hang into a failure


class _Hang(Exception):
    pass


@contextlib.contextmanager
def _time_limit(seconds=LIMIT_S):
    """Raise :class:`_Hang` after ``seconds`` (the refusal must not block)."""
    assert threading.current_thread() is threading.main_thread()

    def expired(signum, frame):
        raise _Hang(f'no answer within {seconds} s (blocked on a special file?)')

    previous = signal.signal(signal.SIGALRM, expired)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def _device(path):
    info = os.stat(path)
    return stat.S_ISCHR(info.st_mode), info.st_rdev, info.st_ino


@pytest.fixture
def special(tmp_path):
    """Return ``{kind: path}``: a FIFO, a listening UNIX socket and the char devices."""
    fifo = tmp_path / 'fifo.yaml'
    os.mkfifo(fifo)
    sock_path = tmp_path / 'sock.yaml'
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.bind(str(sock_path))
    sock.listen(1)
    paths = {'FIFO': str(fifo), 'socket': str(sock_path), 'character device': '/dev/zero',
             'null device': '/dev/null'}
    yield paths
    sock.close()


def _readers():
    from accelcal_ros.camera.rig import load_rig
    from accelcal_ros.lidar.boresight import load_boresight
    from accelcal_ros.lidar.pcd import read_pcd
    from accelcal_ros.lidar.ply import read_ply
    from accelcal_ros.sensor.calibration_file import load_calibration
    from accelcal_ros.sensor.recording import load_recording

    return {'calibration': load_calibration, 'rig': load_rig, 'boresight': load_boresight,
            'recording': load_recording, 'pcd': read_pcd, 'ply': read_ply,
            'bytes': fileio.read_input_bytes,
            'image': lambda p: fileio.read_image_file(p, 0)}


@pytest.mark.parametrize('reader', sorted(_readers()))
def test_readers_refuse_devices_fifos_and_sockets_at_once(special, reader):
    """Each reader on a FIFO, a socket, /dev/zero, /dev/null: one FileFormatError, no block."""
    read = _readers()[reader]
    before = {k: _device(p) for k, p in special.items() if p.startswith('/dev/')}
    for kind, path in special.items():
        with _time_limit(), pytest.raises(FileFormatError) as info:
            read(path)
        message = str(info.value)
        assert '\n' not in message and path in message
        expected = 'character device' if path.startswith('/dev/') else kind
        assert f'is a {expected}' in message and 'not a regular file' in message, message
    assert {k: _device(p) for k, p in special.items() if p.startswith('/dev/')} == before


def test_fifo_swapped_in_after_the_check_does_not_block(tmp_path, monkeypatch):
    """The open uses O_NONBLOCK and fstat: a FIFO that replaces the file is refused."""
    fifo = tmp_path / 'x.yaml'
    os.mkfifo(fifo)
    monkeypatch.setattr(filecheck, 'check_regular_file', lambda path, what='file': None)
    with _time_limit(), pytest.raises(FileFormatError, match='FIFO'):
        fileio.read_input_bytes(fifo, 'calibration file')


def test_reads_are_bounded_by_the_size_limit_of_the_format(tmp_path, monkeypatch):
    """A file beyond its format's limit is refused with the limit, whatever its content."""
    path = tmp_path / 'big.yaml'
    path.write_text('a: [' + ', '.join(['1.0'] * 5000) + ']\n')
    assert textformats.load_yaml_mapping(path)['a'][0] == 1.0
    monkeypatch.setitem(fileio.SIZE_LIMITS, 'yaml', 2**20 // 64)
    with pytest.raises(FileFormatError,
                       match='larger .* than the 0 MiB this package reads from a yaml file'):
        textformats.load_yaml_mapping(path)
    # every kind has a stated limit, none beyond what a 64-bit process could hold
    assert set(fileio.SIZE_LIMITS) >= {'yaml', 'csv', 'point cloud', 'image', 'text line'}
    assert all(0 < v <= 4 * 2**30 for v in fileio.SIZE_LIMITS.values())


def test_calibration_from_dev_zero_and_a_fifo_in_cli_is_one_line(tmp_path, capsys,
                                                                 monkeypatch):
    """`accelcal attitude --calibration /dev/zero|FIFO REC`: status 1, one line, quick."""
    from accelcal_ros.cli import main
    from accelcal_ros.sensor.recording import save_recording

    monkeypatch.chdir(tmp_path)
    t = np.arange(50) * 0.01
    save_recording('rec.csv', t, np.tile([0.0, 0.0, 9.80665], (50, 1)))
    os.mkfifo('cal.yaml')
    for calibration, kind in (('/dev/zero', 'character device'), ('cal.yaml', 'FIFO')):
        with _time_limit():
            status = main(['attitude', '--calibration', calibration, 'rec.csv'])
        err = capsys.readouterr().err.strip().splitlines()
        assert status == 1 and len(err) == 1, err
        assert err[0].startswith('accelcal: error: ') and kind in err[0]
    with _time_limit():  # a recording that is a device: refused the same way
        assert main(['attitude', '/dev/zero']) == 1
    assert 'character device' in capsys.readouterr().err


@pytest.mark.parametrize('device', ['/dev/null', '/dev/full', '/dev/zero'])
def test_writer_refuses_a_device_before_writing(tmp_path, device):
    """A char device as target: FileWriteError before any write; the node stays a device."""
    before = _device(device)
    with pytest.raises(FileWriteError, match='character device, not a regular file'):
        fileio.write_text_atomic(device, 'x\n')
    with pytest.raises(FileWriteError, match='character device'):
        fileio.write_text_atomic(device, 'x\n', backup=True)
    assert _device(device) == before
    link = tmp_path / 'out.yaml'
    link.symlink_to(device)  # written through a link: still the device behind it
    with pytest.raises(FileWriteError, match='character device'):
        fileio.write_text_atomic(link, 'x\n')
    assert os.path.islink(link) and _device(device) == before


def test_writer_refuses_a_fifo_and_a_socket_and_leaves_them(tmp_path, special):
    """A FIFO or socket at the target: refused, still a FIFO/socket, no temporary left."""
    for kind in ('FIFO', 'socket'):
        path = special[kind]
        mode = os.stat(path).st_mode
        with _time_limit(), pytest.raises(FileWriteError, match=kind.split()[0]):
            fileio.write_text_atomic(path, 'x\n', backup=True)
        assert os.stat(path).st_mode == mode
    assert not [f for f in os.listdir(tmp_path) if f.endswith(fileio.TEMP_SUFFIX)]
    assert not [f for f in os.listdir(tmp_path) if f.endswith('.bak')]


def test_backup_is_the_old_file_itself_not_a_copy(tmp_path):
    """`.bak` is the previous inode (hard link or rename): nothing is read or copied."""
    path = tmp_path / 'cal.yaml'
    path.write_text('old\n')
    os.chmod(path, 0o640)
    old_inode = os.stat(path).st_ino
    fileio.write_text_atomic(path, 'new\n', backup=True)
    assert (tmp_path / 'cal.yaml.bak').read_text() == 'old\n'
    assert os.stat(tmp_path / 'cal.yaml.bak').st_ino == old_inode
    assert path.read_text() == 'new\n' and os.stat(path).st_ino != old_inode
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o640
    fileio.write_text_atomic(path, 'newer\n', backup=True)
    assert (tmp_path / 'cal.yaml.bak').read_text() == 'new\n'
    assert sorted(os.listdir(tmp_path)) == ['cal.yaml', 'cal.yaml.bak']


def test_backup_by_rename_where_hard_links_fail(tmp_path, monkeypatch):
    """Without hard links the old file is renamed to .bak (same inode, no copy)."""
    path = tmp_path / 'cal.yaml'
    path.write_text('old\n')
    old_inode = os.stat(path).st_ino

    def no_link(*args, **kwargs):
        raise PermissionError(1, 'Operation not permitted')

    monkeypatch.setattr(os, 'link', no_link)
    fileio.write_text_atomic(path, 'new\n', backup=True)
    assert os.stat(tmp_path / 'cal.yaml.bak').st_ino == old_inode
    assert path.read_text() == 'new\n'


def test_no_write_inside_an_input_directory(tmp_path):
    """Anything inside a bag the command reads, or an existing file of a data set: refused."""
    bag = tmp_path / 'bag'
    bag.mkdir()
    (bag / 'metadata.yaml').write_text('x: 1\n')
    with fileio.guard_inputs([str(bag)]):
        for target, backup in ((bag / 'metadata.yaml', False), (bag / 'metadata.yaml', True),
                               (bag / 'new.yaml', True), (bag / 'sub' / 'x.csv', False)):
            with pytest.raises(InputError, match='inside .*a directory the command reads'):
                fileio.write_text_atomic(target, 'y: 2\n', backup=backup)
        fileio.write_text_atomic(tmp_path / 'beside.yaml', 'y: 2\n')  # beside: allowed
    assert (bag / 'metadata.yaml').read_text() == 'x: 1\n'
    assert sorted(os.listdir(bag)) == ['metadata.yaml']
    data = tmp_path / 'poses'  # a data set (not a bag): its files are inputs, new ones not
    data.mkdir()
    (data / 'pos01.pcd').write_text('points\n')
    with fileio.guard_inputs([str(data)]):
        with pytest.raises(InputError, match='a directory the command reads'):
            fileio.write_text_atomic(data / 'pos01.pcd', 'y\n', backup=True)
        fileio.write_text_atomic(data / 'result.yaml', 'y: 2\n')
    assert (data / 'pos01.pcd').read_text() == 'points\n'


def test_apply_into_the_bag_it_reads_is_refused_and_the_bag_survives(tmp_path, capsys,
                                                                     monkeypatch):
    """`accelcal apply --calibration cal.yaml BAGDIR -o BAGDIR/metadata.yaml`: status 1."""
    from accelcal_ros.cli import main
    from accelcal_ros.recording.sim_bags import write_imu_bag

    monkeypatch.chdir(tmp_path)
    t = np.arange(40) * 0.01
    write_imu_bag(tmp_path / 'bag', 'mcap', t, np.tile([0.0, 0.1, 9.8], (40, 1)))
    _calibration('cal.yaml')
    before = {f: (tmp_path / 'bag' / f).read_bytes() for f in os.listdir(tmp_path / 'bag')}
    for output in ('bag/metadata.yaml', 'bag/out.csv', 'bag'):
        status = main(['apply', '--calibration', 'cal.yaml', 'bag', '-o', output])
        err = capsys.readouterr().err.strip().splitlines()
        assert status == 1 and len(err) == 1, err
        assert 'a directory the command reads' in err[0] or 'also an input' in err[0], err
    after = {f: (tmp_path / 'bag' / f).read_bytes() for f in os.listdir(tmp_path / 'bag')}
    assert after == before
    assert main(['apply', '--calibration', 'cal.yaml', 'bag', '-o', 'out.csv']) == 0


def test_a_bag_whose_storage_is_a_link_keeps_it(tmp_path, capsys, monkeypatch):
    """
    `-o` naming the file a bag's storage links to (symbolic or hard link): status 1.

    The check compared the bag directory only: `accelcal calibrate bag -o store.mcap`
    with `bag/x.mcap -> ../store.mcap` wrote the calibration over the recording, status 0.
    """
    from accelcal_ros.cli import main
    from accelcal_ros.recording.sim_bags import write_imu_bag

    monkeypatch.chdir(tmp_path)
    write_imu_bag(tmp_path / 'bag', 'mcap', np.arange(40) * 0.01,
                  np.tile([0.0, 0.1, 9.8], (40, 1)))
    storage = next(f for f in os.listdir('bag') if f.endswith('.mcap'))
    # the target named like an output these commands write: only the link check refuses
    os.rename(f'bag/{storage}', 'store.csv')
    os.symlink('../store.csv', f'bag/{storage}')
    os.mkdir('hard')
    os.link('store.csv', f'hard/{storage}')
    (tmp_path / 'hard' / 'metadata.yaml').write_bytes((tmp_path / 'bag' / 'metadata.yaml')
                                                      .read_bytes())
    _calibration('cal.yaml')
    before = (tmp_path / 'store.csv').read_bytes()
    for args in (['attitude', 'bag', '-o', 'store.csv'],
                 ['apply', '--calibration', 'cal.yaml', 'hard', '-o', 'store.csv']):
        status = main(args)
        err = capsys.readouterr().err.strip().splitlines()
        assert status == 1 and len(err) == 1, (args, err)
        assert 'a file of' in err[0] and 'through a link' in err[0], err
    assert (tmp_path / 'store.csv').read_bytes() == before


def _calibration(path):
    fileio.write_text_atomic(path, textformats.dump_yaml({
        'format': 'accelcal_ros/calibration 1', 'model': 'full',
        'scale': [1.01, 0.99, 1.002], 'bias': [0.01, -0.02, 0.003],
        'misalignment': [0.001, -0.002, 0.0005]}))


def test_calibrate_onto_a_device_leaves_it_a_device(tmp_path, capsys, monkeypatch):
    """`accelcal apply ... -o /dev/full`: one line, status 1, /dev/full still a device."""
    from accelcal_ros.cli import main
    from accelcal_ros.sensor.recording import save_recording

    monkeypatch.chdir(tmp_path)
    save_recording('rec.csv', np.arange(20) * 0.01, np.tile([0.0, 0.0, 9.80665], (20, 1)))
    _calibration('cal.yaml')
    before = _device('/dev/full')
    with _time_limit():
        status = main(['apply', '--calibration', 'cal.yaml', 'rec.csv', '-o', '/dev/full'])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 1 and len(err) == 1 and 'character device' in err[0], err
    assert _device('/dev/full') == before
    # refused before any work: a calibration that would fail later is not even tried
    assert main(['calibrate', 'rec.csv', '-o', '/dev/null']) == 1
    err = capsys.readouterr()
    assert 'output /dev/null is a character device' in err.err and not err.out


def test_bag_with_a_fifo_inside_is_refused(tmp_path):
    """A rosbag2 directory whose storage file is a FIFO: refused before rosbags opens it."""
    from accelcal_ros.recording.bag import BagReader

    bag = tmp_path / 'bag'
    bag.mkdir()
    os.mkfifo(bag / 'bag_0.mcap')
    with _time_limit(), pytest.raises(FileFormatError, match='FIFO'):
        BagReader(bag)
    os.mkfifo(tmp_path / 'x.mcap')
    with _time_limit(), pytest.raises(FileFormatError, match='FIFO'):
        BagReader(tmp_path / 'x.mcap')


def test_existing_output_problems_are_found_before_any_work(tmp_path):
    """The check the nodes' output_file parameters use (empty, directory, device)."""
    assert filecheck.existing_output_problem(str(tmp_path / 'new.yaml')) is None
    assert 'character device' in filecheck.existing_output_problem('/dev/full')
    assert 'directory' in filecheck.existing_output_problem(str(tmp_path))
    assert 'empty' in filecheck.existing_output_problem('')
    assert isinstance(AccelcalError(), Exception)


@pytest.mark.parametrize('exe', ['calibration', 'lidar_calibration', 'rig_calibration',
                                 'cloud_assembler'])
def test_output_file_parameters_refuse_devices_directories_and_empty(tmp_path, exe):
    """Every node's output_file: /dev/full and a directory refused; empty only where 'none'."""
    from accelcal_ros.node_params import node_specs

    spec = {s.name: s for s in node_specs(exe)}['output_file']
    for bad in ('/dev/full', '/dev/null', str(tmp_path)):
        value, reason = spec.check(bad)
        assert value is None and reason.startswith('output_file: '), (bad, reason)
    _, reason = spec.check('')
    assert (reason is None) == (exe == 'cloud_assembler'), reason
    good = str(tmp_path / ('cloud.ply' if exe == 'cloud_assembler' else 'out.yaml'))
    assert spec.check(good) == (good, None)
