r"""
Every ``accelcal`` command of the README runs as printed, in order, on the sample data.

A new user's journey: ``accelcal sample-data DIR`` writes the simulated recordings under
the README's names; then each ``accelcal ...`` line of the README's ```bash blocks (with
its ``\`` continuations, and the ``echo ... | accelcal p2p-solve`` pipeline) runs in DIR
through bash, exactly as a user would paste it, and must exit 0. Lines that need hardware
or a running ROS graph (``ros2 ...``, the nodes) are not ``accelcal`` commands; an
``accelcal`` line ending in ``# hardware`` (an I2C or SPI bus) or in ``serves until Ctrl-C``
(``accelcal serve``, tested in a browser by its own tests) is skipped.
"""
import os
import re
import shlex
import subprocess
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
README = os.path.join(REPO, 'README.md')


def _logical_lines(block):
    r"""Join ``\`` continuations and lines inside an open quote into one command each."""
    pending = ''
    for line in block.splitlines():
        pending = f'{pending}\n{line}' if pending else line
        try:
            shlex.split(pending.rstrip('\\'), comments=True)
        except ValueError:          # an open quote: the command goes on
            continue
        if pending.rstrip().endswith('\\'):
            continue
        yield pending
        pending = ''
    if pending:
        yield pending


def readme_commands(text):
    """Return the README's ``accelcal`` command lines, in order (skipped ones marked)."""
    commands = []
    for block in re.findall(r'```bash\n(.*?)```', text, re.S):
        for command in _logical_lines(block):
            stripped = command.strip()
            first = stripped.split(None, 1)[0] if stripped else ''
            if first == 'accelcal' or (first == 'echo' and '| accelcal' in stripped):
                commands.append((stripped, stripped.endswith(('# hardware',
                                                              'serves until Ctrl-C'))))
    return commands


def test_parser_finds_every_journey():
    """The parser sees the commands of every journey (a README edit cannot hide them)."""
    with open(README, encoding='utf-8') as handle:
        commands = [c for c, _ in readme_commands(handle.read())]
    names = {c.split()[1] if c.startswith('accelcal') else 'p2p-solve' for c in commands}
    assert {'calibrate', 'apply', 'attitude', 'record', 'rig-calibrate', 'stitch', 'p2p',
            'p2p-solve', 'boresight', 'georeference', 'study', 'sample-data'} <= names
    assert any('\n' in c for c in commands)            # continuations joined


def test_every_readme_command_runs_as_printed(tmp_path):
    """In a fresh directory: sample-data, then every command in README order exits 0."""
    with open(README, encoding='utf-8') as handle:
        commands = readme_commands(handle.read())
    env = dict(os.environ)
    # the installed `accelcal` (tools/env.sh puts it on PATH); else the module, as the README
    # says (`python -m accelcal_ros`)
    shim = tmp_path / 'bin'
    shim.mkdir()
    (shim / 'accelcal').write_text(f'#!/bin/sh\nexec {shlex.quote(sys.executable)} -m '
                                   'accelcal_ros "$@"\n')
    (shim / 'accelcal').chmod(0o755)
    env['PATH'] = f'{shim}{os.pathsep}{env.get("PATH", "")}'
    env['ACCELCAL_PROGRESS'] = '0'
    env['MPLBACKEND'] = 'Agg'
    work = tmp_path / 'journey'
    work.mkdir()
    failures = []
    ran = 0
    for command, skipped in commands:
        if skipped:
            continue
        result = subprocess.run(['bash', '-c', command], cwd=work, env=env, text=True,
                                capture_output=True, timeout=900)
        ran += 1
        if result.returncode != 0:
            failures.append(f'$ {command}\n-> exit {result.returncode}: '
                            f'{result.stderr.strip()[-600:]}')
    assert ran >= 20
    assert not failures, '\n\n'.join(failures)


if __name__ == '__main__':
    pytest.main([__file__, '-q'])
