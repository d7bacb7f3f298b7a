"""How long a node that failed at start-up waits for a /rosout reader (ACCELCAL_ROSOUT_WAIT_S)."""
from accelcal_ros.rosutil import runner
import pytest


@pytest.mark.parametrize('value, expected', [(None, runner.ROSOUT_WAIT_S), ('30', 30.0),
                                             ('0', 0.0), ('-1', runner.ROSOUT_WAIT_S),
                                             ('61', runner.ROSOUT_WAIT_S),
                                             ('nan', runner.ROSOUT_WAIT_S),
                                             ('soon', runner.ROSOUT_WAIT_S)])
def test_rosout_wait_comes_from_the_environment_within_bounds(monkeypatch, value, expected):
    """Unset, malformed or out of 0-60 s: the 3 s default; otherwise the value."""
    if value is None:
        monkeypatch.delenv('ACCELCAL_ROSOUT_WAIT_S', raising=False)
    else:
        monkeypatch.setenv('ACCELCAL_ROSOUT_WAIT_S', value)
    assert runner._rosout_wait_s() == expected
