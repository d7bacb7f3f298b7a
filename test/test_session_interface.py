"""The calibration interface's rules and the output-path checks, without ROS."""
import os

from accelcal_ros.errors import CalibrationError
from accelcal_ros.node_params import node_specs
from accelcal_ros.outputs import DEFAULT_OUTPUT_DIR, output_path_problem
from accelcal_ros.session_interface import (SessionProgress, SessionState, STATUS_KEYS,
                                            status_message, status_values)
import pytest

CALIBRATION_NODES = ('calibration', 'rig_calibration', 'lidar_calibration')


def test_refusals_follow_the_session_state():
    """Start twice, capture/cancel/finish without a session, finish with nothing: refused."""
    state = SessionState('x_calibration')
    for what in ('capture', 'cancel', 'finish'):
        with pytest.raises(CalibrationError, match='call x_calibration/start first'):
            state.check_active(what)
    state.check_start(0)
    state.active = True
    with pytest.raises(CalibrationError, match='already running .3 captures.'):
        state.check_start(3)
    with pytest.raises(CalibrationError, match='nothing captured yet: do this; then call '
                       'x_calibration/finish'):
        state.check_finish(0, 'do this')
    state.check_finish(1, 'do this')
    assert 'session stays open' in state.solve_failed('too few')


def test_status_values_start_with_the_common_keys():
    """The common keys come first, in order; unknown values are empty; extras follow."""
    progress = SessionProgress(2, 6, None, None, 'add poses', {'cam0.views': '2',
                                                               'captures': 'ignored'})
    values = status_values(progress, True, 'captured pose01', '/tmp/rig.yaml')
    assert list(values)[:len(STATUS_KEYS)] == list(STATUS_KEYS)
    assert values['captures'] == '2' and values['coverage_percent'] == ''
    assert values['predicted_error_deg'] == '' and values['cam0.views'] == '2'
    full = status_values(SessionProgress(12, 10, 0.994, 0.04321), False, '', '')
    assert (full['coverage_percent'], full['predicted_error_deg']) == ('99', '0.0432')
    assert status_message('n', progress, True) == 'session running: 2 of 6 captures; add poses'
    assert status_message('n', progress, False) == 'idle: call n/start'


@pytest.mark.parametrize('node', CALIBRATION_NODES)
def test_every_calibration_node_writes_under_the_default_directory(node):
    """Outputs default to ~/.ros/accelcal/ and status_period_s is the shared spec."""
    specs = {s.name: s for s in node_specs(node)}
    assert specs['output_file'].default.startswith(DEFAULT_OUTPUT_DIR + os.sep)
    assert not specs['status_period_s'].read_only
    assert specs['output_file'].check('')[1]


def test_output_path_problems(tmp_path):
    """Empty, wrong extension, a directory, below a file: each refused with the reason."""
    (tmp_path / 'file.txt').write_text('x')
    assert output_path_problem(str(tmp_path / 'new' / 'deeper' / 'out.yaml'), ('.yaml',)) is None
    assert 'empty' in output_path_problem(' ')
    assert 'must end with .yaml' in output_path_problem(str(tmp_path / 'out.txt'), ('.yaml',))
    assert 'is a directory' in output_path_problem(str(tmp_path))
    assert 'is a file' in output_path_problem(str(tmp_path / 'file.txt' / 'x.yaml'))
    assert output_path_problem(str(tmp_path / 'dir'), directory=True) is None
    assert 'is a file' in output_path_problem(str(tmp_path / 'file.txt'), directory=True)
