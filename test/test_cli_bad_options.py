"""
Table-driven test of bad ``accelcal`` options: one line, a status, never a traceback.

The table is built from the parser itself: every numeric option of every subcommand
(those whose type is ``int``/``float`` or one of :mod:`accelcal_ros.cli_args`) is given
``0``, ``-1``, ``nan``, ``inf``, ``1e999`` and ``text``; each value its type rejects must
end with status 2 and one ``accelcal: error:`` line naming the option. No numeric option
may accept NaN, infinity or text (a new ``type=float`` option fails here until it uses
:mod:`accelcal_ros.cli_args`).
"""
import argparse
import os
import subprocess
import sys

from accelcal_ros import cli
from accelcal_ros.cli import build_parser, main
import numpy as np
import pytest

BAD_VALUES = ('0', '-1', 'nan', 'inf', '1e999', 'text')
NEVER_VALID = ('nan', 'inf', '1e999', 'text')


def _subcommands(parser, prefix=()):
    """Yield ``(argv prefix, subparser)`` for every leaf subcommand."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield prefix, parser
        return
    for action in subs:
        for name, sub in action.choices.items():
            yield from _subcommands(sub, prefix + (name,))


def _is_numeric(action):
    kind = action.type
    return kind in (int, float) or getattr(kind, '__module__', '') == 'accelcal_ros.cli_args'


def _rejects(action, value):
    try:
        action.type(value)
    except (argparse.ArgumentTypeError, TypeError, ValueError):
        return True
    return action.choices is not None and action.type(value) not in action.choices


def numeric_options():
    """Every ``(argv prefix, action)`` of a numeric option."""
    return [(prefix, action) for prefix, sub in _subcommands(build_parser())
            for action in sub._actions if action.option_strings and _is_numeric(action)]


def _argv(prefix, action, value):
    count = action.nargs if isinstance(action.nargs, int) else 1
    return [*prefix, action.option_strings[-1], *([value] * count)]


CASES = [(prefix, action, value) for prefix, action in numeric_options()
         for value in BAD_VALUES if _rejects(action, value)]


def test_the_table_covers_the_options_of_the_issue():
    """Every subcommand's numeric options are in the table (the issue's four included)."""
    names = {(' '.join(p), a.option_strings[-1]) for p, a, _ in CASES}
    for expected in [('calibrate', '--window-s'), ('calibrate', '--min-still-s'),
                     ('record', '--duration'), ('study boresight', '--trials')]:
        assert expected in names
    assert len(CASES) >= 150


def test_no_numeric_option_accepts_nan_infinity_or_text():
    """A numeric option whose type lets NaN/inf/text through is a bug (use cli_args)."""
    loose = [f'accelcal {" ".join(p)} {a.option_strings[-1]} {v}'
             for p, a in numeric_options() for v in NEVER_VALID if not _rejects(a, v)]
    assert not loose, 'accepted: ' + '; '.join(loose)
    unchecked = [f'accelcal {" ".join(p)} {a.option_strings[-1]}' for p, a in numeric_options()
                 if a.type in (int, float) and a.choices is None]
    assert not unchecked, 'plain int/float (no range; use cli_args): ' + '; '.join(unchecked)


WORKLOAD_DESTS = ('trials', 'count', 'seeds', 'package_count')
HUGE = '10000000000'


def _workload_options():
    """Every ``study`` option that sets how much work a run does (trials, counts, seeds)."""
    return [(p, a) for p, a in numeric_options()
            if p[:1] == ('study',) and a.dest in WORKLOAD_DESTS]


def test_every_study_workload_option_has_an_upper_bound(capsys):
    """``--trials 10000000000`` is one line and status 2, not a MemoryError or a day's run."""
    names = {(' '.join(p), a.option_strings[-1]) for p, a in _workload_options()}
    for expected in [('study p2p', '--trials'), ('study p2p', '--package-count'),
                     ('study calibration', '--trials'), ('study motion', '--seeds'),
                     ('study horizon', '--count'), ('study roi', '--count'),
                     ('study boresight', '--trials')]:
        assert expected in names
    for prefix, action in _workload_options():
        assert _rejects(action, HUGE), f'{" ".join(prefix)} {action.option_strings[-1]}'
        assert main(_argv(prefix, action, HUGE)) == 2
        captured = capsys.readouterr()
        lines = captured.err.strip().splitlines()
        assert len(lines) == 1 and 'must be at most' in lines[0], captured.err
        assert captured.out == ''


@pytest.mark.parametrize('prefix, action, value', CASES,
                         ids=[f'{" ".join(p)} {a.option_strings[-1]} {v}' for p, a, v in CASES])
def test_bad_numeric_option_is_one_line_and_status_2(capsys, prefix, action, value):
    """Status 2, one ``accelcal: error:`` line naming the option, nothing else."""
    assert main(_argv(prefix, action, value)) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('accelcal: error:'), captured.err
    assert action.option_strings[-1] in lines[0] and 'Traceback' not in captured.err
    assert captured.out == ''


def test_runtime_errors_are_one_line_and_status_1(tmp_path, capsys):
    """A missing input, a directory as input or as output: one line, status 1."""
    rec = tmp_path / 'rec.csv'
    rec.write_text('t,ax,ay,az\n0,0,0,9.8\n')
    for argv in (['calibrate', str(tmp_path / 'none.csv'), '-o', str(tmp_path / 'c.yaml')],
                 ['calibrate', str(tmp_path), '-o', str(tmp_path / 'c.yaml')],
                 ['record', '-o', str(tmp_path), '--duration', '1'],
                 ['record', '-o', '/proc/accelcal.csv', '--duration', '1']):
        assert main(argv) == 1, argv
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and err.startswith('accelcal: error:'), err


def test_unexpected_exception_is_one_line_with_a_hint(monkeypatch, capsys):
    """A bug inside a handler: one line naming ACCELCAL_DEBUG; with it, the traceback."""
    def broken(args):
        raise RuntimeError('boom')

    real = cli.build_parser

    def patched():
        parser = real()
        parser.set_defaults(handler=broken)
        for _, sub in _subcommands(parser):
            sub.set_defaults(handler=broken)
        return parser

    monkeypatch.setattr(cli, 'build_parser', patched)
    monkeypatch.delenv('ACCELCAL_DEBUG', raising=False)
    assert main(['error-budget']) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and 'ACCELCAL_DEBUG=1' in err and 'boom' in err
    monkeypatch.setenv('ACCELCAL_DEBUG', '1')
    with pytest.raises(RuntimeError):
        main(['error-budget'])


def test_out_of_memory_is_one_line_not_an_internal_error(monkeypatch, capsys):
    """A MemoryError (numpy: a 30000x30000 panorama on a small machine) is the user's to fix."""
    def hungry(args):
        raise MemoryError('Unable to allocate 2.51 GiB for an array with shape (30000, 30000)')

    real = cli.build_parser

    def patched():
        parser = real()
        for _, sub in _subcommands(parser):
            sub.set_defaults(handler=hungry)
        return parser

    monkeypatch.setattr(cli, 'build_parser', patched)
    assert main(['error-budget']) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert err.startswith('accelcal: error: out of memory') and '2.51 GiB' in err
    assert 'internal error' not in err


def test_the_installed_command_never_prints_a_traceback(tmp_path):
    """The real process: bad option (2), missing file (1), help mentions ACCELCAL_DEBUG."""
    env = dict(os.environ)
    env.pop('ACCELCAL_DEBUG', None)
    run = [sys.executable, '-m', 'accelcal_ros']
    for argv, status in ((['calibrate', 'x.csv', '-o', 'c.yaml', '--window-s', '0'], 2),
                         (['record', '-o', str(tmp_path / 'r.csv'), '--duration', 'nan'], 2),
                         (['study', 'boresight', '--trials', '0'], 2),
                         (['apply', str(tmp_path / 'none.csv'), '--calibration', 'c.yaml',
                           '-o', str(tmp_path / 'out.csv')], 1)):
        proc = subprocess.run(run + argv, capture_output=True, text=True, env=env,
                              timeout=120)
        assert proc.returncode == status, (argv, proc.stderr)
        assert len(proc.stderr.strip().splitlines()) == 1 and 'Traceback' not in proc.stderr
    helptext = subprocess.run(run + ['--help'], capture_output=True, text=True, env=env,
                              timeout=120).stdout
    assert 'ACCELCAL_DEBUG=1' in helptext


def test_empty_scan_and_malformed_p2p_mount_are_clear_errors(tmp_path, capsys, monkeypatch):
    """An empty scan to georeference: one line; p2p-solve: a bad mount line, stream goes on."""
    import io
    import json

    from accelcal_ros.lidar.cloud import make_cloud, write_cloud
    from accelcal_ros.lidar.poses import PoseStream, write_poses_csv
    import numpy as np

    write_cloud(str(tmp_path / 'empty.ply'), make_cloud(np.zeros((0, 3)), time=np.zeros(0)))
    t = np.arange(5) * 0.1
    write_poses_csv(tmp_path / 'poses.csv',
                    PoseStream(t, np.zeros((5, 3)), np.tile([0, 0, 0, 1.0], (5, 1))))
    (tmp_path / 'bs.yaml').write_text('rpy_deg: [0, 0, 0]\n')
    assert main(['georeference', '--cloud', str(tmp_path / 'empty.ply'), '--poses',
                 str(tmp_path / 'poses.csv'), '--boresight', str(tmp_path / 'bs.yaml'),
                 '-o', str(tmp_path / 'out.pcd')]) == 1
    err = capsys.readouterr().err
    assert 'no points' in err and len(err.strip().splitlines()) == 1
    problem = {'uv': [[700, 500], [500, 520]], 'K': [1000, 0, 640, 0, 1000, 480, 0, 0, 1],
               'points': [[0, 0, 0], [1, 0, 0]], 'roll': 0.1, 'pitch': 0.2}
    lines = [json.dumps(dict(problem, imu_to_camera=mount))
             for mount in ('abc', [[1, 'x', 0]], [1, 0, 0, 0, 1, 0, 0, 0, 1])]
    monkeypatch.setattr('sys.stdin', io.StringIO('\n'.join(lines) + '\n'))
    assert main(['p2p-solve']) == 1
    out = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert len(out) == 3 and 'imu_to_camera' in out[0]['error']
    assert 'imu_to_camera' in out[1]['error'] and out[2]['solutions']


def test_two_outputs_with_one_path_are_refused(tmp_path, capsys):
    """`calibrate -o c.yaml --plot c.yaml` would overwrite its own calibration: refused."""
    rec = tmp_path / 'rec.csv'
    rec.write_text('t,ax,ay,az\n0,0,0,9.8\n')
    out = tmp_path / 'c.yaml'
    assert main(['calibrate', str(rec), '-o', str(out), '--plot', str(out)]) == 1
    err = capsys.readouterr().err
    assert 'two outputs' in err and len(err.strip().splitlines()) == 1 and not out.exists()


def test_dash_and_a_storage_suffix_are_not_outputs(tmp_path, capsys, monkeypatch):
    """
    Refuse ``-o -`` and a bag output named like a storage file, in one line each.

    ``-o -`` wrote a file named ``-``; ``apply -o y.db3`` made a folder ``y.db3`` holding
    ``y.db3.mcap``. Now status 1 and nothing written.
    """
    from accelcal_ros.recording.sim_bags import write_imu_bag

    monkeypatch.chdir(tmp_path)
    rec = tmp_path / 'rec.csv'
    rec.write_text('t,ax,ay,az\n0,0,0,9.8\n0.01,0,0,9.8\n')
    assert main(['attitude', str(rec), '-o', '-']) == 1
    assert 'standard output' in capsys.readouterr().err and not (tmp_path / '-').exists()
    write_imu_bag(tmp_path / 'bag', 'mcap', np.arange(20) * 0.01,
                  np.tile([0.0, 0.1, 9.8], (20, 1)))
    (tmp_path / 'c.yaml').write_text('format: accelcal_ros/calibration 1\nmodel: full\n'
                                     'scale: [1, 1, 1]\nbias: [0, 0, 0]\n'
                                     'misalignment: [0, 0, 0]\n')
    for name in ('y.db3', 'y.mcap'):
        assert main(['apply', 'bag', '--calibration', 'c.yaml', '-o', name]) == 1
        err = capsys.readouterr().err
        assert 'a rosbag2 bag is a directory' in err and err.count('\n') == 1, err
        assert not (tmp_path / name).exists()


@pytest.mark.parametrize('argv, suffix', [
    (['calibrate', 'rec.csv', '-o', 'calib.png'], '.yaml or .yml'),
    (['attitude', 'rec.csv', '-o', 'att.yaml'], '.csv'),
    (['boresight', 'positions', '-o', 'positions/pos16.ply'], '.yaml or .yml'),
    (['p2p', 'bag', '-o', 'p.yaml'], '.csv'),
    (['rig-calibrate', 'capture', '--board', '9x6', '--square-m', '0.025', '-o', 'r.csv'],
     '.yaml or .yml')])
def test_an_output_named_for_another_format_is_refused(tmp_path, capsys, monkeypatch, argv,
                                                       suffix):
    """
    Refuse an output whose extension is not the format written, before any work.

    `calibrate -o calib.png` wrote YAML, `boresight -o positions/pos16.ply` a file the
    next run read as a scan.
    """
    monkeypatch.chdir(tmp_path)
    for folder in ('positions', 'bag', 'capture'):
        (tmp_path / folder).mkdir()
    (tmp_path / 'rec.csv').write_text('t,ax,ay,az\n0,0,0,9.8\n0.01,0,0,9.8\n')
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert f'must end with {suffix}' in err and err.count('\n') == 1, err
    assert not os.path.exists(argv[argv.index('-o') + 1])


@pytest.mark.parametrize('argv', [
    ['study', 'roi', '--json', '{dir}'],
    ['study', 'p2p', '--json', '{dir}'],
    ['study', 'motion', '--drive-out', '{tmp}/drive.csv', '--odometry-out', '{dir}'],
    ['boresight', '{tmp}/positions', '-o', '{tmp}/bs.yaml', '--plot', '{dir}'],
    ['calibrate', '{tmp}/rec.csv', '-o', '{tmp}/c.yaml', '--plot', '{dir}'],
    ['georeference', '--cloud', 'a.pcd', '--poses', 'p.csv', '--boresight', 'b.yaml',
     '-o', '{dir}'],
    ['rig-calibrate', 'capture', '--board', '9x6', '--square-m', '0.025', '-o', '{dir}'],
])
def test_a_directory_for_a_file_output_is_refused_before_the_command_runs(tmp_path, argv):
    """A plot, a JSON table, a study's CSV, -o of a file writer: a folder there is refused."""
    from accelcal_ros.errors import InputError

    folder = tmp_path / 'DIR'
    folder.mkdir()
    args = build_parser().parse_args([a.format(dir=folder, tmp=tmp_path) for a in argv])
    ran = []
    args.handler = ran.append
    with pytest.raises(InputError, match='DIR is a directory; give a file name'):
        cli.run_command(args)
    assert not ran and os.listdir(folder) == []


@pytest.mark.parametrize('argv', [
    ['rig-calibrate', 'capture', '--board', '9x6', '--square-m', '0.025', '-o', '{out}'],
    ['calibrate', '{tmp}/rec.csv', '-o', '{out}'],
    ['record', '--backend', 'sim', '--duration', '1', '-o', '{out}'],
    ['apply', 'in.mcap', '--calibration', 'c.yaml', '-o', '{out}'],
    ['study', 'horizon', '--out', '{out}'],
])
def test_an_output_under_a_file_is_refused_before_the_command_runs(tmp_path, argv):
    """-o FILE/x (a file where a folder must be, a folder output too): refused before any work."""
    from accelcal_ros.errors import InputError

    blocker = tmp_path / 'FILE'
    blocker.write_text('keep me\n')
    out = blocker / 'sub' / 'out.yaml'
    args = build_parser().parse_args([a.format(out=out, tmp=tmp_path) for a in argv])
    ran = []
    args.handler = ran.append
    with pytest.raises(InputError, match='FILE is a file, not a directory'):
        cli.run_command(args)
    assert not ran and blocker.read_text() == 'keep me\n'


@pytest.mark.parametrize('argv', [['sample-data', '{dir}'],
                                  ['apply', 'in.mcap', '--calibration', 'c.yaml', '-o', '{dir}'],
                                  ['study', 'horizon', '--out', '{dir}']])
def test_a_folder_output_may_be_an_existing_directory(tmp_path, argv):
    """Outputs that are folders (a data set, a rosbag2, frames) are left to the command."""
    folder = tmp_path / 'DIR'
    folder.mkdir()
    args = build_parser().parse_args([a.format(dir=folder) for a in argv])
    ran = []
    args.handler = ran.append
    cli.run_command(args)
    assert len(ran) == 1


def test_p2p_solve_input_file_with_bytes_that_are_not_utf8(tmp_path, capsys):
    """A line of bytes that are not UTF-8 gets its error; the following lines are solved."""
    import json

    good = json.dumps({'uv': [[700, 500], [500, 520]], 'K': [1000, 0, 640, 0, 1000, 480, 0,
                                                             0, 1],
                       'points': [[0, 0, 0], [1, 0, 0]], 'down': [0, 0.8, 0.6]})
    path = tmp_path / 'problems.jsonl'
    path.write_bytes(b'\xff\xfe{\n' + good.encode() + b'\n')
    assert main(['p2p-solve', '--input', str(path)]) == 1
    out = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert len(out) == 2 and 'JSON' in out[0]['error'] and out[1]['solutions']
