"""The horizon study (paper A Fig. 6): closed form, rendered measurement, calibration row."""
import math

from accelcal_ros.panorama import horizon_study
from accelcal_ros.panorama.projection import PanoramaGeometry
from accelcal_ros.sensor.model import paper_a_model, SensorModel
import numpy as np
import pytest


def test_closed_form_horizon():
    """No error: a flat horizon at (H-1)/2; a pitch error of 2 deg: 40 px at azimuth 0."""
    g = PanoramaGeometry(3600, 2400, 180.0, 120.0)
    true = (0.0, horizon_study.REFERENCE_PITCH_RAD)
    flat = horizon_study.analytic_horizon_rows(g, true, true)
    assert np.allclose(flat, 1199.5)
    for error_deg in (-2.0, 2.0):
        used = (0.0, true[1] + math.radians(error_deg))
        rows = horizon_study.analytic_horizon_rows(g, true, used)
        assert np.abs(rows - 1199.5).max() == pytest.approx(40.0, abs=0.05)
        # pitch error = rotation about the horizontal axis: no shift at azimuth +-90 deg
        assert abs(rows[0] - 1199.5) < 0.1
    # a roll error tilts the horizon: opposite signs left and right of the heading
    rows = horizon_study.analytic_horizon_rows(g, true, (math.radians(1.0), true[1]))
    assert (rows[900] - 1199.5) * (rows[2700] - 1199.5) < 0


def test_tilt_errors_of_perfect_and_biased_calibrations():
    """The true model gives zero tilt error; a 0.01 g x-bias about 0.6 deg of pitch."""
    truth = paper_a_model(500)
    biased = SensorModel(truth.scale, truth.bias + [0.01, 0.0, 0.0], truth.misalignment)
    roll_err, pitch_err = horizon_study.tilt_errors_after_calibration([truth, biased], truth)
    assert abs(roll_err[0]) < 1e-12 and abs(pitch_err[0]) < 1e-12
    assert abs(math.degrees(pitch_err[1])) == pytest.approx(0.6, abs=0.1)


def test_quick_study_rendered_matches_closed_form(tmp_path):
    """The quick study's rendered horizon agrees with the closed form within a pixel."""
    truth = paper_a_model(500)
    rng = np.random.default_rng(0)
    models = [SensorModel(truth.scale * (1 + rng.normal(0, 1e-3, 3)),
                          truth.bias + rng.normal(0, 1e-3, 3)) for _ in range(5)]
    lines = []
    result = horizon_study.run(quick=True, models=models, out_dir=str(tmp_path),
                               say=lines.append)
    assert result['truth_offset_px'] < 0.3 and result['columns_seen'] > 0.9 * 1800
    for row in result['rows'].values():
        assert row['rendered_px'] == pytest.approx(20.0, abs=0.5)
        assert row['model_misfit_px'] < 0.5
    assert 0.0 < result['calibration']['deviation_px_max'] < 5.0
    assert any('paper' in line for line in lines)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        'horizon_pitch_error_+2deg.png', 'horizon_pitch_error_-2deg.png', 'horizon_true.png']
