"""The sensor model (identity default, paper A Table 1, gravity fit) and datasheet facts."""
from accelcal_ros.driver.sim_sensor import SimulatedAdxl345
from accelcal_ros.errors import InputError
from accelcal_ros.sensor.datasheet import (datasheet_noise_std_g, FULL_RES_G_PER_LSB,
                                           NOISE_STD_100HZ_G)
from accelcal_ros.sensor.model import paper_a_model, PAPER_A_TABLE1, SensorModel
from accelcal_ros.sensor.units import g_to_mps2, mps2_to_g, STANDARD_GRAVITY_M_S2
import numpy as np
import pytest


def test_default_is_identity_and_simulator_truth_is_paper_a():
    model = SensorModel()
    assert model.is_identity()
    raw = np.array([[0.1, -0.2, 0.97]])
    assert np.array_equal(model.correct(raw), raw)
    truth = SimulatedAdxl345().truth
    assert truth.scale.tolist() == [0.928, 0.909, 0.896]
    assert truth.bias.tolist() == [-0.025, -0.037, -0.056]
    assert not truth.is_identity()
    for positions, (scale, bias) in PAPER_A_TABLE1.items():
        assert paper_a_model(positions).scale.tolist() == list(scale)
    with pytest.raises(InputError, match='K = 100, 300 or 500'):
        paper_a_model(12)


def test_gravity_fit_tells_a_matching_from_a_mismatched_calibration():
    rng = np.random.default_rng(0)
    directions = rng.normal(size=(15, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    truth = paper_a_model(500)
    raw = truth.distort(directions) + rng.normal(0.0, 0.003, (15, 3))
    own = truth.gravity_fit(raw)
    assert own.fits and own.count == 15
    assert own.mean_norm_g == pytest.approx(1.0, abs=0.003) and own.std_norm_g < 0.005
    other = paper_a_model(100).gravity_fit(raw)   # another sensor's calibration
    assert not other.fits and 'does not fit' in other.message()
    assert abs(other.mean_norm_g - 1.0) > 0.03 or other.std_norm_g > 0.03
    none = SensorModel().gravity_fit(raw)         # uncalibrated: |g| 0.85-0.95
    assert not none.fits and none.mean_norm_g < 0.95
    nan_rows = np.vstack([raw, [[np.nan, 0, 1]]])
    assert truth.gravity_fit(nan_rows).count == 15
    assert not truth.gravity_fit(np.empty((0, 3))).fits


def test_datasheet_noise_and_units():
    assert FULL_RES_G_PER_LSB == 0.0039
    assert datasheet_noise_std_g(100.0) == pytest.approx([0.002925, 0.002925, 0.00429])
    assert datasheet_noise_std_g(400.0) == pytest.approx(2 * np.array(NOISE_STD_100HZ_G))
    assert g_to_mps2(1.0) == STANDARD_GRAVITY_M_S2 == 9.80665
    assert mps2_to_g([9.80665, 0.0]) == pytest.approx([1.0, 0.0])
