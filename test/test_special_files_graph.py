"""
Graph tests: nodes given a special file or a bad command line give one clear line.

``calibration`` with ``output_file:=/dev/full`` (status 1, one line), ``attitude`` with
``calibration_file:=/dev/zero`` (one error line at start-up, then uncalibrated as for any
bad file; at run time refused at once, the node keeps answering, its memory does not
grow) and rcl's own command-line errors
(``-p model:=``, ``--params-file /nonexistent.yaml``): status 1 and one FATAL line, no
traceback.
"""
import os
import stat

import pytest

pytestmark = pytest.mark.graph


def _lines(proc):
    return [line for line in proc.output().splitlines() if line.strip()]


@pytest.mark.parametrize('args, expected', [
    (('--ros-args', '-p', 'model:='), "Couldn't parse parameter override rule: '-p model:='"),
    (('--ros-args', '--params-file', '/nonexistent.yaml'),
     "Couldn't parse params file: '--params-file /nonexistent.yaml'"),
])
def test_rcl_argument_errors_are_one_line(graph, args, expected):
    """Status 1, one FATAL line naming the executable, no RCLError traceback."""
    proc = graph.start('attitude', args=args)
    assert proc.wait_exit(timeout=30.0) == 1
    lines = _lines(proc)
    assert len(lines) == 1, lines
    assert '[FATAL]' in lines[0] and '[attitude]' in lines[0]
    assert 'bad command-line arguments: ' + expected in lines[0]
    assert ' at /' not in lines[0] and 'error not set' not in lines[0]


def test_calibration_node_refuses_dev_full_as_output_file(graph):
    """``output_file:=/dev/full``: one line at start-up, /dev/full still a device."""
    before = os.stat('/dev/full')
    proc = graph.start('calibration', {'output_file': '/dev/full'})
    assert proc.wait_exit(timeout=30.0) == 1
    lines = _lines(proc)
    assert len(lines) == 1, lines
    assert 'output_file: /dev/full is a character device, not a regular file' in lines[0]
    after = os.stat('/dev/full')
    assert stat.S_ISCHR(after.st_mode) and after.st_rdev == before.st_rdev


def _rss_kib(pid):
    with open(f'/proc/{pid}/status') as handle:
        for line in handle:
            if line.startswith('VmRSS:'):
                return int(line.split()[1])
    return 0


def test_attitude_refuses_dev_zero_and_a_fifo_as_calibration_file(graph, tmp_path):
    """
    Start-up: one FATAL line and status 1 (it ran on uncalibrated, with an ERROR line).

    At run time the file is refused at once with the reason, the node keeps answering and
    its memory does not grow.
    """
    fifo = tmp_path / 'cal.yaml'
    os.mkfifo(fifo)
    failed = graph.start('attitude', {'calibration_file': '/dev/zero'}, name='attitude_bad')
    assert failed.wait_exit(timeout=30.0) == 1
    lines = _lines(failed)
    assert len(lines) == 1 and '[FATAL]' in lines[0], lines
    assert '/dev/zero: is a character device' in lines[0], lines
    proc = graph.start('attitude')
    assert graph.get_parameters('attitude', ['calibration_file'], timeout=30.0) == {
        'calibration_file': ''}
    rss = _rss_kib(proc.proc.pid)
    for path, kind in (('/dev/zero', 'character device'), (str(fifo), 'FIFO')):
        result = graph.set_parameters('attitude', {'calibration_file': path}, timeout=30.0)
        assert not result[0].successful and kind in result[0].reason, result[0].reason
    assert _rss_kib(proc.proc.pid) < rss + 50_000  # nothing read from the device
    assert proc.proc.poll() is None and 'Traceback' not in proc.output()
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
