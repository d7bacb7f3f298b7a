"""ament_pep257 over the package, as ``colcon test`` runs it."""
import os

from ament_pep257.main import main
import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.linter
def test_pep257():
    """Docstrings follow PEP 257 (ament's rule set)."""
    rc = main(argv=[os.path.join(REPO, 'accelcal_ros')])
    assert rc == 0, 'Found code style errors / warnings'
