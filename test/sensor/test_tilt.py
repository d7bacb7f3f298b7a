"""Tilt estimator: angles against truth, covariance, smoothing, acceleration, pitch +-90."""
import math

from accelcal_ros.frames import roll_pitch_from_specific_force, specific_force_from_roll_pitch
from accelcal_ros.sensor.model import PAPER_K500_BIAS, PAPER_K500_SCALE, SensorModel
from accelcal_ros.sensor.tilt import (angle_jacobian, estimate_many, quaternion_from_roll_pitch,
                                      TiltEstimator)
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

TRUTH = SensorModel(PAPER_K500_SCALE, PAPER_K500_BIAS, (0.005, -0.004, 0.006))


@settings(max_examples=50, deadline=None)
@given(st.floats(-3.1, 3.1), st.floats(-1.5, 1.5))
def test_noise_free_calibrated_reading_gives_true_roll_pitch(roll, pitch):
    est = TiltEstimator(TRUTH).update(0.0, TRUTH.distort(
        specific_force_from_roll_pitch(roll, pitch)))
    assert est.pitch == pytest.approx(pitch, abs=1e-9)
    assert math.remainder(est.roll - roll, 2 * math.pi) == pytest.approx(0.0, abs=1e-8)
    assert not est.accelerating


@pytest.mark.parametrize('pitch_deg', [90.0, -90.0, 89.999, -89.9999])
def test_no_nan_at_pitch_90(pitch_deg):
    raw = TRUTH.distort(specific_force_from_roll_pitch(0.3, math.radians(pitch_deg)))
    est = TiltEstimator(TRUTH, time_constant_s=0.1).update(0.0, raw)
    values = [est.roll, est.pitch, *est.covariance.ravel(), *quaternion_from_roll_pitch(
        est.roll, est.pitch)]
    assert all(math.isfinite(v) for v in values)
    assert est.pitch == pytest.approx(math.radians(pitch_deg), abs=1e-6)
    assert est.covariance[0, 0] <= math.pi ** 2


@settings(max_examples=30, deadline=None)
@given(st.floats(-3.1, 3.1), st.floats(-1.5, 1.5))
def test_quaternion_matches_scipy_yaw_zero(roll, pitch):
    q = quaternion_from_roll_pitch(roll, pitch)
    expected = Rotation.from_euler('xyz', [roll, pitch, 0.0]).as_quat()
    assert np.allclose(q, expected) or np.allclose(q, -expected)


@settings(max_examples=30, deadline=None)
@given(st.floats(-3.0, 3.0), st.floats(-1.4, 1.4))
def test_angle_jacobian_matches_finite_differences(roll, pitch):
    f = specific_force_from_roll_pitch(roll, pitch)
    numeric = np.empty((2, 3))
    for i in range(3):
        step = np.zeros(3)
        step[i] = 1e-7
        plus = np.array(roll_pitch_from_specific_force(f + step))
        minus = np.array(roll_pitch_from_specific_force(f - step))
        numeric[:, i] = (plus - minus) / 2e-7
    np.testing.assert_allclose(angle_jacobian(f), numeric, atol=1e-5)


def test_covariance_matches_the_scatter_of_noisy_estimates():
    rng = np.random.default_rng(0)
    noise = np.array([0.0029, 0.0029, 0.0043])
    roll, pitch = math.radians(20.0), math.radians(-35.0)
    raw = TRUTH.distort(specific_force_from_roll_pitch(roll, pitch))
    samples = raw + rng.standard_normal((4000, 3)) * noise
    est = TiltEstimator(TRUTH, noise_std_g=noise)
    out = estimate_many(est, np.arange(4000) * 0.01, samples)
    angles = np.array([[e.roll, e.pitch] for e in out])
    predicted = np.sqrt(np.diag(out[0].covariance))
    np.testing.assert_allclose(angles.std(axis=0), predicted, rtol=0.1)


def test_calibration_uncertainty_adds_to_the_covariance():
    raw = TRUTH.distort([0.0, 0.0, 1.0])
    plain = TiltEstimator(TRUTH).update(0.0, raw).covariance
    with_cal = TiltEstimator(TRUTH, tilt_std_rad=math.radians(0.05)).update(0.0, raw).covariance
    np.testing.assert_allclose(np.diag(with_cal) - np.diag(plain),
                               math.radians(0.05) ** 2, rtol=1e-6)


def test_smoothing_lowers_noise_and_its_reported_variance():
    rng = np.random.default_rng(1)
    raw = TRUTH.distort(specific_force_from_roll_pitch(0.2, 0.1))
    samples = raw + rng.standard_normal((3000, 3)) * 0.004
    t = np.arange(3000) * 0.01
    fast = estimate_many(TiltEstimator(TRUTH, noise_std_g=[0.004] * 3), t, samples)
    slow = estimate_many(TiltEstimator(TRUTH, noise_std_g=[0.004] * 3, time_constant_s=0.5),
                         t, samples)
    fast_std = np.std([e.pitch for e in fast[500:]])
    slow_std = np.std([e.pitch for e in slow[500:]])
    assert slow_std < fast_std / 5
    assert slow[-1].covariance[1, 1] < fast[-1].covariance[1, 1] / 25
    np.testing.assert_allclose(np.sqrt(slow[-1].covariance[1, 1]), slow_std, rtol=0.3)


def test_acceleration_flagged_estimate_held_and_covariance_inflated():
    est = TiltEstimator(TRUTH)
    level = TRUTH.distort([0.0, 0.0, 1.0])
    good = est.update(0.0, level)
    shoved = TRUTH.distort([0.5, 0.0, 1.0])  # 0.5 g forward: |f| = 1.118 g
    out = est.update(0.01, shoved)
    assert out.accelerating
    assert out.roll == good.roll and out.pitch == good.pitch
    assert out.covariance[1, 1] > good.covariance[1, 1] + math.asin(0.11) ** 2
    back = est.update(0.02, level)
    assert not back.accelerating


def test_persistent_magnitude_error_is_not_held_forever():
    est = TiltEstimator(TRUTH, max_hold_s=1.0)
    first = est.update(0.0, TRUTH.distort([0.0, 0.0, 1.0]))
    assert not first.accelerating
    # From now on the magnitude stays 15 % low (e.g. a wrong calibration), tilted 0.5 rad.
    tilted = TRUTH.distort(0.85 * specific_force_from_roll_pitch(0.5, 0.0))
    held = est.update(0.5, tilted)
    assert held.accelerating and held.roll == first.roll
    later = est.update(1.6, tilted)
    assert later.accelerating and later.roll == pytest.approx(0.5, abs=1e-6)


def test_uncalibrated_start_is_flagged_not_held():
    est = TiltEstimator(SensorModel.identity())
    raw = TRUTH.distort(specific_force_from_roll_pitch(0.3, 0.2))  # |a| ~ 0.85 g
    out = [est.update(k * 0.01, raw) for k in range(300)]
    assert all(o.accelerating for o in out)
    assert out[-1].pitch == pytest.approx(out[0].pitch)


def test_nan_reading_gives_none_and_bad_settings_rejected():
    assert TiltEstimator().update(0.0, [np.nan, 0.0, 1.0]) is None
    from accelcal_ros.errors import InputError
    with pytest.raises(InputError):
        TiltEstimator(time_constant_s=-1.0)
    with pytest.raises(InputError):
        TiltEstimator(noise_std_g=[0.1, 0.1])


@pytest.mark.parametrize('raw, reason', [
    ([0.0, 0.0, 0.0], 'zero'),
    ([1e300, 0.0, 0.0], 'out of range'),
    ([0.0, 1e200, 1.0], 'out of range'),
    ([2000.0, 0.0, 0.0], 'out of range'),
    ([np.nan, 0.0, 1.0], 'NaN'),
    ([0.0, np.inf, 1.0], 'out of range'),
])
def test_impossible_input_gives_no_tilt(raw, reason):
    est = TiltEstimator(TRUTH)
    assert est.update(0.0, raw) is None and est.last_rejection == reason
    assert est.update(0.01, TRUTH.distort([0.0, 0.0, 1.0])) is not None   # then recovers


def test_free_fall_gives_no_tilt_even_with_calibration():
    est = TiltEstimator(TRUTH)
    assert est.update(0.0, TRUTH.distort([0.0, 0.0, 1.0])) is not None
    assert est.update(0.01, TRUTH.distort([0.01, -0.02, 0.03])) is None   # |f| = 0.04 g
    assert est.last_rejection == 'zero'


@given(st.floats(-3.0, 3.0), st.floats(-1.5, 1.5), st.floats(0.0, 0.9))
@settings(max_examples=50, deadline=None)
def test_float_covariance_equals_the_matrix_formula(roll, pitch, alpha_time):
    """The plain-float path equals ``J C Sigma_a C^T J^T`` computed with numpy."""
    noise = np.array([0.003, 0.002, 0.005])
    est = TiltEstimator(TRUTH, noise_std_g=noise, tilt_std_rad=0.001)
    f = specific_force_from_roll_pitch(roll, pitch)
    out = est.update(0.0, TRUTH.distort(f))
    c = TRUTH.correction_matrix()
    jac = angle_jacobian(f / np.linalg.norm(f))
    cov = jac @ c @ np.diag(noise ** 2) @ c.T @ jac.T + np.eye(2) * 1e-6
    if jac[0, 1] == 0.0 and jac[0, 2] == 0.0 or cov[0, 0] > math.pi ** 2:
        cov[0, 0], cov[0, 1], cov[1, 0] = math.pi ** 2, 0.0, 0.0
    np.testing.assert_allclose(out.covariance, cov, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(out.force_g, f, atol=1e-12)
