"""ament_flake8 over the package, as ``colcon test`` runs it."""
import os
import subprocess
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RUN = ('import sys\n'
       'from ament_flake8.main import main_with_errors\n'
       'rc, errors = main_with_errors(argv=sys.argv[1:])\n'
       'print("\\n".join(errors))\n'
       'sys.exit(rc)\n')


@pytest.mark.linter
def test_flake8():
    """No flake8 errors in the package, tests, tools and benchmarks."""
    paths = [os.path.join(REPO, p) for p in ('accelcal_ros', 'test', 'benchmarks', 'setup.py')]
    # in a fresh process: flake8 forks its workers, and a fork of the test process (its
    # rclpy and DDS threads, after the tests before this one) crashed them in their
    # garbage collection
    done = subprocess.run([sys.executable, '-c', RUN, *paths], capture_output=True,
                          text=True, timeout=600, cwd=REPO)
    errors = sorted({line for line in done.stdout.splitlines() if ':' in line and
                     line.split(':', 1)[0].endswith('.py')})
    assert done.returncode == 0, (f'Found {len(errors)} code style errors / warnings:\n'
                                  + '\n'.join(errors) + done.stderr[-2000:])
