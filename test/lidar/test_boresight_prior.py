"""A prior that the data contradict: the data win (said) or the calibration is refused."""
from accelcal_ros.errors import CalibrationError
from accelcal_ros.frames import rotation_from_rpy_radians
from accelcal_ros.lidar import boresight, scanner_sim as sim
from accelcal_ros.lidar.boresight import calibrate_boresight
from accelcal_ros.lidar.floor_assign import FloorCandidate
from accelcal_ros.lidar.wahba import rotation_angle_deg
import numpy as np
import pytest

TRUTH_RPY_DEG = (0.3, 44.2, -2.1)  # the recording of issue 26
TRUTH = rotation_from_rpy_radians(*np.radians(TRUTH_RPY_DEG))


def _mount(*rpy_deg):
    return rotation_from_rpy_radians(*np.radians(rpy_deg))


@pytest.fixture(scope='module')
def positions():
    """Paper B's 15 positions, simulated once for the module."""
    return sim.positions_for_calibration(sim.simulate_protocol(TRUTH, seed=1))


@pytest.mark.parametrize('prior_rpy_deg', [(0, 44, 180), (0, 0, 0)])
def test_a_contradicting_prior_loses_to_the_data_and_says_so(positions, prior_rpy_deg):
    """Yaw 180 deg off or pitch 44 deg off: the truth (< 0.05 deg), a warning, no drops."""
    res = calibrate_boresight(positions, _mount(*prior_rpy_deg))
    assert rotation_angle_deg(res.rotation, TRUTH) < 0.05
    assert len(res.positions) == 15 and not res.dropped
    said = [w for w in res.warnings if 'contradicts the data' in w]
    assert len(said) == 1 and 'the data win' in said[0], res.warnings
    assert 'rpy [0.3, 44.2, -2.1] deg' in said[0]
    # the uncertainty is the data's (the contradicted prior is not in it)
    assert np.all(res.rpy_std_deg < 0.05)


def test_a_prior_near_the_truth_is_used_without_a_word(positions):
    """A prior 1-5 deg off is consistent: no warning about it."""
    res = calibrate_boresight(positions, _mount(0, 45, 0))
    assert rotation_angle_deg(res.rotation, TRUTH) < 0.05
    assert not [w for w in res.warnings if 'prior' in w]


def _candidate(rpy_deg, ruled_out=''):
    return FloorCandidate(_mount(*rpy_deg), np.zeros(15, int), np.full(15, 0.02),
                          np.full(15, 1.2), ruled_out=ruled_out, positions=list(range(15)))


def test_a_contradicting_prior_with_several_data_candidates_is_refused(positions,
                                                                       monkeypatch):
    """Two assignments left by the data and the prior near neither: refused with them."""
    cands = [_candidate((0, 44, -2)), _candidate((180, 44, -2)),
             _candidate((0, 44, 178), 'its floor would be 1.20-4.50 m below the scanner')]
    monkeypatch.setattr(boresight, 'judged_candidates', lambda *a, **k: cands)
    monkeypatch.setattr(boresight, 'find_planes', lambda *a, **k: [])
    with pytest.raises(CalibrationError) as info:
        calibrate_boresight(positions, _mount(0, 44, 180))
    message = str(info.value)
    assert 'contradicts the data: it selects the assignment rpy [0.0, 44.0, 178.0]' in message
    assert 'ruled out because its floor would be 1.20-4.50 m' in message
    assert '2 assignments are left' in message and '\n' not in message


@pytest.mark.parametrize('text', ['rpy_deg: [true, 0, 0]\n', 'rpy_deg: 1\n',
                                  'R: [1, 0, 0, 0, 1, 0, 0, 0, true]\n',
                                  'rpy_deg: [[1], 2, 3]\n'])
def test_boresight_file_numbers_are_numbers(tmp_path, text):
    """A bool or a nested list is not a number (issue 26: ``true`` read as 1.0)."""
    from accelcal_ros.errors import FileFormatError

    path = tmp_path / 'bs.yaml'
    path.write_text(text)
    with pytest.raises(FileFormatError, match='expected .* numbers'):
        boresight.load_boresight(path)


def test_a_result_at_the_edge_of_the_search_cone_is_said(positions, monkeypatch):
    """When the data cannot check the prior, a result ~15 deg from it is warned about."""
    monkeypatch.setattr(boresight, '_check_prior', lambda prior, *a: (prior, []))
    res = calibrate_boresight(positions, _mount(0, 30, -2))
    assert rotation_angle_deg(res.rotation, _mount(0, 30, -2)) > 13.5  # 14.2 deg here
    assert any('14.2 deg from the prior' in w and 'near the search limit of 15 deg' in w
               for w in res.warnings), res.warnings
    res = calibrate_boresight(positions, _mount(0, 45, 0))
    assert not any('search limit' in w for w in res.warnings)
