"""Atomic writes with backup, and YAML loading errors that name the file."""
import os

from accelcal_ros.errors import FileFormatError
from accelcal_ros.fileio import write_text_atomic, write_with_atomic
from accelcal_ros.textformats import dump_yaml, load_yaml_mapping
import pytest


def test_atomic_write_keeps_backup_and_survives_a_failing_writer(tmp_path):
    """The old file becomes .bak; a writer that raises leaves the old file untouched."""
    path = tmp_path / 'calib.yaml'
    write_text_atomic(path, 'first\n')
    write_text_atomic(path, 'second\n', backup=True)
    assert path.read_text() == 'second\n'
    assert (tmp_path / 'calib.yaml.bak').read_text() == 'first\n'

    def failing(handle):
        handle.write('half')
        raise RuntimeError('disk full')

    with pytest.raises(RuntimeError):
        write_with_atomic(path, failing)
    assert path.read_text() == 'second\n'
    assert sorted(os.listdir(tmp_path)) == ['calib.yaml', 'calib.yaml.bak']


def test_yaml_errors_name_file_and_line(tmp_path):
    """Missing, empty/truncated and invalid YAML are FileFormatErrors with the path."""
    with pytest.raises(FileFormatError, match='not found'):
        load_yaml_mapping(tmp_path / 'none.yaml')
    empty = tmp_path / 'empty.yaml'
    empty.write_text('')
    with pytest.raises(FileFormatError, match='truncated'):
        load_yaml_mapping(empty)
    bad = tmp_path / 'bad.yaml'
    bad.write_text('a: 1\nb: [1, 2\n')
    with pytest.raises(FileFormatError, match='not valid YAML') as info:
        load_yaml_mapping(bad)
    assert info.value.line is not None and str(bad) in str(info.value)
    good = tmp_path / 'good.yaml'
    good.write_text(dump_yaml({'scale': [1.0, 2.0], 'model': 'full'}))
    assert good.read_text().startswith('scale: [1.0, 2.0]\n')
    assert load_yaml_mapping(good) == {'scale': [1.0, 2.0], 'model': 'full'}


def test_readers_name_the_file_for_missing_directory_and_non_utf8(tmp_path):
    """Missing file, directory and non-UTF-8 bytes are FileFormatErrors (with the line)."""
    from accelcal_ros.fileio import read_input_bytes
    from accelcal_ros.textformats import read_numeric_csv

    binary = tmp_path / 'rec.csv'
    binary.write_bytes(b't,ax,ay,az\n0,1,2,3\n\xff\xfe,1,2,3\n')
    for reader in (lambda p: read_numeric_csv(p, ('t', 'ax')), load_yaml_mapping,
                   read_input_bytes):
        with pytest.raises(FileFormatError, match='not found'):
            reader(tmp_path / 'none')
        with pytest.raises(FileFormatError, match='is a directory'):
            reader(tmp_path)
    with pytest.raises(FileFormatError, match='not UTF-8') as info:
        read_numeric_csv(binary, ('t', 'ax'))
    assert info.value.line == 3
    with pytest.raises(FileFormatError, match='not UTF-8'):
        load_yaml_mapping(binary)
    nul = tmp_path / 'nul.csv'
    nul.write_bytes(b't,ax\n0,\x001\n')
    with pytest.raises(FileFormatError):
        read_numeric_csv(nul, ('t', 'ax'))
    date = tmp_path / 'date.yaml'
    date.write_text('when: 2021-13-45\n')  # YAML timestamp that is no date: ValueError
    with pytest.raises(FileFormatError, match='not valid YAML'):
        load_yaml_mapping(date)


@pytest.mark.parametrize('target', ['dir', 'proc', 'readonly', 'file_as_parent'])
def test_write_failures_are_one_error_naming_the_path(tmp_path, target):
    """A directory, /proc, a read-only folder or a file as parent: FileWriteError."""
    from accelcal_ros.errors import FileWriteError

    if target == 'dir':
        path = tmp_path
    elif target == 'proc':
        path = '/proc/accelcal-test.yaml'
    elif target == 'readonly':
        folder = tmp_path / 'ro'
        folder.mkdir()
        folder.chmod(0o555)
        path = folder / 'out.yaml'
        if os.access(folder, os.W_OK):  # root ignores the mode: use /proc/self instead
            path = '/proc/self/accelcal-test.yaml'
    else:
        (tmp_path / 'plain').write_text('x')
        path = tmp_path / 'plain' / 'out.yaml'
    with pytest.raises(FileWriteError) as info:
        write_text_atomic(path, 'data\n')
    assert str(path) in str(info.value) and '\n' not in str(info.value)


def test_atomic_write_keeps_the_mode_and_new_files_follow_the_umask(tmp_path):
    """Replacing a 0644 (or 0640) file keeps its mode; a new file gets 0666 & ~umask."""
    path = tmp_path / 'calib.yaml'
    for mode in (0o644, 0o640, 0o600):
        path.write_text('old\n')
        path.chmod(mode)
        write_text_atomic(path, 'new\n')
        assert path.stat().st_mode & 0o777 == mode and path.read_text() == 'new\n'
    old = os.umask(0o027)
    try:
        write_text_atomic(tmp_path / 'fresh.yaml', 'x\n')
    finally:
        os.umask(old)
    assert (tmp_path / 'fresh.yaml').stat().st_mode & 0o777 == 0o640


def test_stale_temp_files_of_dead_writers_are_removed(tmp_path):
    """A temp file of a pid that no longer runs goes; one of a live pid stays."""
    import subprocess
    import sys

    from accelcal_ros.fileio import TEMP_SUFFIX

    child = subprocess.run([sys.executable, '-c', 'import os; print(os.getpid())'],
                           capture_output=True, text=True, check=True)
    dead = int(child.stdout)
    stale = tmp_path / f'.out.csv.{dead}-0{TEMP_SUFFIX}'
    live = tmp_path / f'.out.csv.{os.getppid()}-0{TEMP_SUFFIX}'
    other = tmp_path / f'.other.csv.{dead}-0{TEMP_SUFFIX}'
    for p in (stale, live, other):
        p.write_text('half')
    write_text_atomic(tmp_path / 'out.csv', 'whole\n')
    assert not stale.exists() and live.exists() and other.exists()
    assert (tmp_path / 'out.csv').read_text() == 'whole\n'


def test_guarded_command_cannot_overwrite_its_inputs(tmp_path):
    """Inside guard_inputs, writing a file that was read (or given) is refused."""
    from accelcal_ros.errors import InputError
    from accelcal_ros.fileio import guard_inputs
    from accelcal_ros.textformats import read_numeric_csv

    rec = tmp_path / 'rec.csv'
    rec.write_text('t,ax\n0,1\n')
    link = tmp_path / 'link.csv'
    os.link(rec, link)
    with guard_inputs():
        read_numeric_csv(rec, ('t', 'ax'))
        for target in (rec, link, tmp_path / '.' / 'rec.csv'):
            with pytest.raises(InputError, match='also an input'):
                write_text_atomic(target, 'gone\n')
        write_text_atomic(rec, 't,ax\n0,2\n', backup=True)  # the input survives as .bak
        write_text_atomic(tmp_path / 'out.csv', 'fine\n')
    assert (tmp_path / 'rec.csv.bak').read_text() == 't,ax\n0,1\n'
    write_text_atomic(rec, 'free again\n')  # outside the guard


@pytest.mark.parametrize('command', [
    ['apply', '{rec}', '--calibration', '{cal}', '-o', '{rec}'],
    ['apply', '{rec}', '--calibration', '{cal}', '-o', '{cal}'],
    ['plot-calibration', '{cal}', '-o', '{cal}'],
    ['calibrate', '{rec}', '-o', '{rec}'],
    ['attitude', '{rec}', '-o', '{rec}'],
    ['georeference', '--cloud', '{pcd}', '--poses', '{rec}', '--boresight', '{cal}',
     '-o', '{pcd}'],
    ['stitch', '--rig', '{cal}', '--roll', '0', '--pitch', '0', '-o', '{pcd}', '{pcd}'],
])
def test_accelcal_refuses_to_write_over_an_input(tmp_path, capsys, command):
    """`accelcal ... -o INPUT` is one error line, status 1, and the input is untouched."""
    from accelcal_ros.cli import main

    files = {'rec': tmp_path / 'rec.csv', 'cal': tmp_path / 'c.yaml',
             'pcd': tmp_path / 'scan.pcd'}
    for name, path in files.items():
        path.write_text(f'{name} content\n')
        path.chmod(0o644)
    argv = [a.format(**{k: str(v) for k, v in files.items()}) for a in command]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert 'also an input' in err and len(err.strip().splitlines()) == 1
    for name, path in files.items():
        assert path.read_text() == f'{name} content\n'


def test_a_writer_killed_before_the_rename_leaves_a_temp_file_the_next_write_removes(tmp_path):
    """A writer that dies mid-write leaves .NAME.PID-N.accelcal-tmp; the next write removes it."""
    import subprocess
    import sys

    from accelcal_ros.fileio import TEMP_SUFFIX

    target = tmp_path / 'calib.yaml'
    target.write_text('old\n')
    code = ('import os, sys\nfrom accelcal_ros import fileio\n'
            'os.replace = lambda *a: os._exit(9)  # killed between fsync and rename\n'
            f'fileio.write_text_atomic({str(target)!r}, "new\\n")\n')
    assert subprocess.run([sys.executable, '-c', code], timeout=60).returncode == 9
    left = [p.name for p in tmp_path.iterdir() if p.name.endswith(TEMP_SUFFIX)]
    assert len(left) == 1 and left[0].startswith('.calib.yaml.') and target.read_text() == 'old\n'
    write_text_atomic(target, 'newer\n')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['calib.yaml']
    assert target.read_text() == 'newer\n'


def test_a_symbolic_link_is_written_through(tmp_path):
    """Writing to a link replaces the file it points at; the link stays a link."""
    real = tmp_path / 'real.yaml'
    real.write_text('old\n')
    link = tmp_path / 'link.yaml'
    link.symlink_to(real)
    write_text_atomic(link, 'new\n')
    assert link.is_symlink() and real.read_text() == 'new\n'


def test_yaml_alias_bomb_and_deep_nesting_are_refused(tmp_path):
    """Nested aliases (billions of values) and 50,000 nested lists: FileFormatError, fast."""
    lines = ['a0: &a0 [1, 2, 3, 4, 5, 6, 7, 8, 9]']
    for k in range(1, 10):
        lines.append(f'a{k}: &a{k} [' + ', '.join([f'*a{k - 1}'] * 9) + ']')
    bomb = tmp_path / 'bomb.yaml'
    bomb.write_text('\n'.join(lines) + '\nscale: *a9\n')
    with pytest.raises(FileFormatError, match='expands to more than'):
        load_yaml_mapping(bomb)
    deep = tmp_path / 'deep.yaml'
    deep.write_text('a: ' + '[' * 50000 + ']' * 50000 + '\n')
    with pytest.raises(FileFormatError, match='not valid YAML'):
        load_yaml_mapping(deep)


def test_a_dense_yaml_under_the_size_limit_is_refused_before_the_parse(tmp_path):
    """Values packed two bytes each: refused at once (was 22 s and 700 MB for 2 MB)."""
    import time

    from accelcal_ros.filecheck import SIZE_LIMITS
    from accelcal_ros.textformats import MAX_YAML_SEPARATORS

    assert SIZE_LIMITS['yaml'] <= 4 * 2**20
    path = tmp_path / 'dense.yaml'
    path.write_text('scale: [' + '1,' * (SIZE_LIMITS['yaml'] // 2 - 10) + '1]\n')
    start = time.monotonic()
    with pytest.raises(FileFormatError, match=f'more than {MAX_YAML_SEPARATORS} YAML sep'):
        load_yaml_mapping(path, 'calibration file')
    assert time.monotonic() - start < 2.0
    path.write_text('scale: [' + '1,' * (MAX_YAML_SEPARATORS - 10) + '1]\n')
    assert len(load_yaml_mapping(path)['scale']) == MAX_YAML_SEPARATORS - 9  # at the limit


def test_yaml_key_given_twice_is_refused_with_its_line(tmp_path):
    """Two equal keys (PyYAML keeps the last): refused, naming the key and both lines."""
    path = tmp_path / 'cal.yaml'
    path.write_text('scale: [1, 1, 1]\nbias: [0, 0, 0]\nnested:\n  a: 1\n  a: 2\n')
    with pytest.raises(FileFormatError, match="key 'a' twice .first on line 4") as info:
        load_yaml_mapping(path)
    assert info.value.line == 5
    path.write_text('scale: [1, 1, 1]\nbias: [0, 0, 0]\nscale: [2, 2, 2]\n')
    with pytest.raises(FileFormatError, match="key 'scale' twice"):
        load_yaml_mapping(path)
    path.write_text('base: &b {x: 1, y: 2}\nd:\n  <<: *b\n  x: 3\n')  # a merge overrides
    assert load_yaml_mapping(path)['d'] == {'x': 3, 'y': 2}


def test_integer_beyond_a_double_names_its_key(tmp_path, capsys):
    """scale: [1e400 as digits]: 'value too large' naming the key, not an internal error."""
    from accelcal_ros.cli import main
    from accelcal_ros.textformats import yaml_number

    assert yaml_number(10 ** 400) == float('inf') and yaml_number(-10 ** 400) < 0
    path = tmp_path / 'cal.yaml'
    path.write_text('model: diagonal\nscale: [1' + '0' * 400 + ', 1, 1]\nbias: [0, 0, 0]\n')
    with pytest.raises(FileFormatError, match=r'"scale\[0\]" in the file holds a value too'):
        load_yaml_mapping(path)
    boresight = tmp_path / 'bs.yaml'
    boresight.write_text('rpy_deg: [1' + '0' * 400 + ', 0, 0]\n')
    (tmp_path / 'cloud.pcd').write_text('x')
    status = main(['georeference', '--cloud', str(tmp_path / 'cloud.pcd'), '--poses',
                   str(tmp_path / 'poses.csv'), '--boresight', str(boresight),
                   '-o', str(tmp_path / 'out.ply')])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 1 and len(err) == 1, err
    assert 'rpy_deg[0]' in err[0] and 'too large' in err[0], err


def test_the_largest_real_yaml_a_rosbag2_metadata_file_is_read(tmp_path):
    """1000 topics with QoS and 4000 split files (1.4 MB): 107000 separators, refused at 1e5."""
    from accelcal_ros.textformats import _separator_count, MAX_YAML_SEPARATORS

    qos = ('      offered_qos_profiles:\n      - avoid_ros_namespace_conventions: false\n'
           '        deadline:\n          nsec: 0\n          sec: 0\n        depth: 5\n'
           '        durability: volatile\n        history: keep_last\n        lifespan:\n'
           '          nsec: 0\n          sec: 0\n        liveliness: system_default\n'
           '        liveliness_lease_duration:\n          nsec: 0\n          sec: 0\n'
           '        reliability: best_effort\n')
    files = ''.join(f'  - duration:\n      nanoseconds: 1490000000\n    message_count: 242\n'
                    f'    path: bag_{k}.mcap\n    starting_time:\n'
                    '      nanoseconds_since_epoch: 1700000000000000000\n' for k in range(4000))
    topics = ''.join(f'  - message_count: 150\n    topic_metadata:\n      name: /t{k}\n' + qos
                     + '      serialization_format: cdr\n      type: sensor_msgs/msg/Imu\n'
                     '      type_description_hash: RIHS01_7d9a00ff131080897a5ec7e26e3159\n'
                     for k in range(1000))
    text = ('rosbag2_bagfile_information:\n  duration:\n    nanoseconds: 1490000000\n'
            '  files:\n' + files + '  message_count: 242\n  relative_file_paths:\n'
            + ''.join(f'  - bag_{k}.mcap\n' for k in range(4000))
            + '  storage_identifier: mcap\n  topics_with_message_count:\n' + topics)
    assert 100_000 < _separator_count(text) <= MAX_YAML_SEPARATORS
    path = tmp_path / 'metadata.yaml'
    path.write_text(text)
    info = load_yaml_mapping(path)['rosbag2_bagfile_information']
    assert len(info['files']) == 4000 and len(info['topics_with_message_count']) == 1000


def test_missing_folders_are_what_makedirs_makes_and_removed_only_if_empty(tmp_path):
    """The pair a failed run uses to take away the folders it made, and nothing else."""
    from accelcal_ros.fileio import missing_folders, remove_empty_folders

    path = tmp_path / 'a' / 'b' / 'c'
    made = missing_folders(path)
    assert made == [str(tmp_path / 'a'), str(tmp_path / 'a' / 'b'), str(path)]
    assert missing_folders(tmp_path) == []
    os.makedirs(path)
    (tmp_path / 'a' / 'b' / 'keep.txt').write_text('x')
    remove_empty_folders(made)
    assert not path.exists() and (tmp_path / 'a' / 'b' / 'keep.txt').exists()
