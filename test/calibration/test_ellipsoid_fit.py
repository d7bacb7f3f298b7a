"""LM ellipsoid fit (paper A eq. 5) against simulated ground truth."""
from accelcal_ros.calibration.coverage import recommended_directions, unit_directions
from accelcal_ros.calibration.ellipsoid_fit import (fit_ellipsoid, params_to_model,
                                                    residuals_and_jacobian)
from accelcal_ros.calibration.study import simulate_position_means
from accelcal_ros.errors import CalibrationError, InputError
from accelcal_ros.sensor.model import paper_a_model, PAPER_K500_BIAS, PAPER_K500_SCALE, SensorModel
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

MISALIGNED = SensorModel(PAPER_K500_SCALE, PAPER_K500_BIAS, (0.008, -0.006, 0.01))


@pytest.mark.parametrize('model', ['diagonal', 'full'])
def test_noise_free_fit_recovers_the_truth(model):
    truth = paper_a_model(500) if model == 'diagonal' else MISALIGNED
    raw = truth.distort(recommended_directions(14))
    fit = fit_ellipsoid(raw, np.full((14, 3), 1e-4), model=model)
    np.testing.assert_allclose(fit.sensor_model.scale, truth.scale, atol=1e-9)
    np.testing.assert_allclose(fit.sensor_model.bias, truth.bias, atol=1e-9)
    np.testing.assert_allclose(fit.sensor_model.misalignment, truth.misalignment, atol=1e-9)
    assert fit.residual_rms_g < 1e-9
    assert fit.positions == 14 and not fit.dropped


def test_noisy_fit_within_its_standard_deviations_and_covariance_is_honest():
    rng = np.random.default_rng(4)
    truth = MISALIGNED
    errors, stds = [], []
    for _ in range(60):
        means, sd = simulate_position_means(truth, recommended_directions(12), 100, rng)
        fit = fit_ellipsoid(means, sd, model='full', holdout=False)
        errors.append(fit.parameters - np.concatenate(
            [truth.scale, truth.bias, truth.misalignment]))
        stds.append(fit.std)
    errors, stds = np.array(errors), np.array(stds)
    z = errors / stds
    # Normalised errors have unit spread if the covariance is right (loose: 60 trials).
    assert 0.6 < np.sqrt(np.mean(z ** 2)) < 1.6
    assert np.all(np.abs(errors[:, 3:6]) < 1e-3)  # bias better than 1 mg


def test_diagonal_model_cannot_absorb_misalignment_full_can():
    rng = np.random.default_rng(1)
    means, sd = simulate_position_means(MISALIGNED, recommended_directions(24), 100, rng)
    diagonal = fit_ellipsoid(means, sd, model='diagonal')
    full = fit_ellipsoid(means, sd, model='full')
    assert diagonal.residual_rms_g > 5 * full.residual_rms_g
    assert full.predicted_tilt_error_deg < 0.1


def test_moving_position_is_dropped_with_a_warning():
    rng = np.random.default_rng(2)
    truth = paper_a_model(500)
    means, sd = simulate_position_means(truth, recommended_directions(14), 100, rng)
    # Position 5 averaged while turning 30 deg: the mean is shorter than 1 g.
    means[5] = truth.bias + (means[5] - truth.bias) * np.cos(np.radians(15.0))
    fit = fit_ellipsoid(means, sd, model='full')
    assert fit.dropped == [5]
    assert any('position 5 dropped' in w and 'moving' in w for w in fit.warnings)
    np.testing.assert_allclose(fit.sensor_model.bias, truth.bias, atol=1e-3)
    assert abs(fit.residuals_g[5]) > 0.01


def test_too_few_positions_refused_with_what_to_do():
    raw = paper_a_model(500).distort(recommended_directions(6))
    with pytest.raises(CalibrationError, match='at least 10'):
        fit_ellipsoid(raw, model='full')


def test_positions_in_one_cone_refused_with_hint():
    rng = np.random.default_rng(3)
    directions = unit_directions(rng.normal([0.0, 0.0, 1.0], 0.15, size=(15, 3)))
    raw = paper_a_model(500).distort(directions)
    with pytest.raises(CalibrationError) as info:
        fit_ellipsoid(raw, np.full((15, 3), 3e-4), model='full')
    message = str(info.value)
    assert 'do not constrain' in message and '+z up' in message and 'Add positions' in message


def test_bad_input_rejected():
    with pytest.raises(InputError):
        fit_ellipsoid(np.zeros((12, 2)))
    raw = paper_a_model(500).distort(recommended_directions(12))
    raw[3, 1] = np.nan
    with pytest.raises(InputError, match='NaN'):
        fit_ellipsoid(raw)
    with pytest.raises(InputError, match='model'):
        fit_ellipsoid(paper_a_model(500).distort(recommended_directions(12)), model='ellipse')


def test_holdout_reported_and_near_the_noise():
    rng = np.random.default_rng(5)
    means, sd = simulate_position_means(paper_a_model(500), recommended_directions(14), 100, rng)
    fit = fit_ellipsoid(means, sd)
    assert fit.holdout_rms_g is not None
    assert fit.residual_rms_g <= fit.holdout_rms_g < 2e-3


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-0.05, 0.05), min_size=9, max_size=9))
def test_analytic_jacobian_matches_finite_differences(offsets):
    params = np.concatenate([[0.93, 0.91, 0.9], [-0.02, 0.03, -0.05], [0.01, -0.01, 0.005]])
    params = params + np.array(offsets)
    raw = params_to_model(params, 'full').distort(recommended_directions(12)) * 1.01
    _, jac = residuals_and_jacobian(params, raw, 'full')
    numeric = np.empty_like(jac)
    for i in range(9):
        step = np.zeros(9)
        step[i] = 1e-7
        numeric[:, i] = (residuals_and_jacobian(params + step, raw, 'full')[0]
                         - residuals_and_jacobian(params - step, raw, 'full')[0]) / 2e-7
    np.testing.assert_allclose(jac, numeric, atol=1e-6)
