"""ament_flake8 over the package, as ``colcon test`` runs it."""
import os

from ament_flake8.main import main_with_errors
import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.linter
def test_flake8():
    """No flake8 errors in the package, tests, tools and benchmarks."""
    paths = [os.path.join(REPO, p) for p in ('accelcal_ros', 'test', 'benchmarks', 'setup.py')]
    rc, errors = main_with_errors(argv=paths)
    assert rc == 0, f'Found {len(errors)} code style errors / warnings:\n' + '\n'.join(errors)
