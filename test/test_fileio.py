"""Atomic writes with backup, and YAML loading errors that name the file."""
import os

from accelcal_ros.errors import FileFormatError
from accelcal_ros.fileio import dump_yaml, load_yaml_mapping, write_text_atomic, write_with_atomic
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
