"""Sphere coverage, predicted error and hints."""
from accelcal_ros.calibration.coverage import (coverage_fraction, describe_direction,
                                               predicted_tilt_error_deg, recommended_directions,
                                               suggest_directions, tilt_errors_rad)
from accelcal_ros.sensor.model import paper_a_model
import numpy as np


def test_recommended_sets_cover_the_sphere():
    for count in (12, 14, 24):
        d = recommended_directions(count)
        assert d.shape == (count, 3)
        np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
        assert coverage_fraction(d) == 1.0
    assert coverage_fraction([[0.0, 0.0, 1.0]]) < 0.15
    assert coverage_fraction(np.zeros((0, 3))) == 0.0


def test_suggestions_point_away_from_captured():
    names = suggest_directions([[0.0, 0.0, 1.0]], count=1)
    assert names[0].startswith('-z up (upside down)')
    assert suggest_directions(recommended_directions(26 * 0 + 14), count=3,
                              min_separation_deg=60.0) == []


def test_describe_direction_uses_rep103_roll_pitch():
    assert describe_direction([0.0, 1.0, 0.0]) == '+y up (roll 90, pitch 0 deg)'
    assert describe_direction([1.0, 0.0, 0.0]).startswith('+x up (roll 0, pitch -90')


def test_tilt_errors_zero_for_the_truth_and_predicted_error_scales_with_covariance():
    truth = paper_a_model(500)
    roll_err, pitch_err = tilt_errors_rad(truth, [truth])
    assert np.abs(roll_err).max() < 1e-12 and np.abs(pitch_err).max() < 1e-12
    cov = np.eye(9) * 1e-8
    small = predicted_tilt_error_deg(truth, cov, 'full')
    large = predicted_tilt_error_deg(truth, cov * 100, 'full')
    assert 0 < small < large
    np.testing.assert_allclose(large / small, 10.0, rtol=0.05)
