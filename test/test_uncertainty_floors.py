"""An uncertainty is never reported smaller than the error a check inside the program knows."""
import dataclasses

from accelcal_ros.calibration.coverage import (fibonacci_directions, predicted_tilt_error_deg,
                                               recommended_directions)
from accelcal_ros.calibration.ellipsoid_fit import fit_ellipsoid
from accelcal_ros.lidar import scanner_sim as sim
from accelcal_ros.lidar.boresight import _honest_std, calibrate_boresight, HALVES_95
from accelcal_ros.lidar.wahba import rotation_covariance, rpy_std_deg
from accelcal_ros.sensor.calibration_file import load_calibration
from accelcal_ros.sensor.model import SensorModel
from accelcal_ros.textformats import dump_yaml
from accelcal_ros.uncertainty import (floor_at_known_error, floor_each_at_known_error,
                                      KnownError)
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

TRUTH_MODEL = SensorModel(np.array([1.02, 0.98, 1.01]), np.array([0.02, -0.03, 0.01]),
                          np.array([0.002, -0.001, 0.003]))


def test_rule_raises_to_the_largest_known_error_and_says_why():
    """Below a known error: raised, with the check named; above or unknown: unchanged."""
    value, note = floor_at_known_error(0.1, [KnownError(0.5, 'check A'), None,
                                             KnownError(0.3, 'check B')], ' deg', 'sigma')
    assert value == 0.5 and 'check A' in note and '0.1' in note and 'sigma' in note
    assert floor_at_known_error(0.6, [KnownError(0.5, 'A')]) == (0.6, None)
    assert floor_at_known_error(0.1, [KnownError(float('nan'), 'A')]) == (0.1, None)
    assert floor_at_known_error(float('inf'), [KnownError(1.0, 'A')])[0] == float('inf')
    values, note = floor_each_at_known_error([0.1, 0.7, 0.2], [KnownError(0.5, 'A')])
    assert values.tolist() == [0.5, 0.7, 0.5] and '2 values' in note


def _fit(directions, seed, spread_g=0.003):
    rng = np.random.default_rng(seed)
    force = directions * (1 + rng.normal(0, spread_g, len(directions)))[:, None]
    return fit_ellipsoid(TRUTH_MODEL.distort(force), np.full((len(directions), 3), 1e-4),
                         model='full')


def test_calibration_fit_predicted_error_not_below_its_hold_out():
    """11 positions, 9 parameters: the hold-out knows a larger error than the covariance."""
    fit = _fit(fibonacci_directions(11), seed=3)
    known = np.degrees(np.arcsin(fit.holdout_rms_g))
    nominal = predicted_tilt_error_deg(fit.sensor_model, fit.covariance, 'full')
    assert nominal < known  # the case this test is about
    assert fit.predicted_tilt_error_deg >= known
    assert any('hold-out residual' in w and 'raised' in w for w in fit.warnings)


def test_calibration_fit_normal_case_unchanged():
    """24 well-spread positions: the predicted error is the covariance's, no note."""
    fit = _fit(np.vstack([recommended_directions(12), recommended_directions(14)[6:],
                          -recommended_directions(14)[6:8]]), seed=0, spread_g=0.0002)
    nominal = predicted_tilt_error_deg(fit.sensor_model, fit.covariance, 'full')
    assert fit.predicted_tilt_error_deg == pytest.approx(nominal)
    assert not any('raised' in w for w in fit.warnings)


def _calibration_file(tmp_path, **extra):
    data = {'format': 'accelcal_ros/calibration 1', 'model': 'diagonal',
            'scale': [1.0, 1.0, 1.0], 'bias': [0.0, 0.0, 0.0]}
    data.update(extra)
    path = tmp_path / 'cal.yaml'
    path.write_text(dump_yaml(data))
    return str(path)


def test_calibration_file_predicted_error_not_below_its_own_residuals(tmp_path):
    """A file claiming 0.001 deg beside a 10 mg hold-out residual reads as >= 0.57 deg."""
    record = load_calibration(_calibration_file(
        tmp_path, predicted_tilt_error_deg=0.001, residual_rms_g=0.002, holdout_rms_g=0.01))
    assert record.predicted_tilt_error_deg >= np.degrees(np.arcsin(0.01))
    assert len(record.notes) == 1 and 'hold-out' in record.notes[0]
    record = load_calibration(_calibration_file(
        tmp_path, predicted_tilt_error_deg=0.05, residual_rms_g=0.0002, holdout_rms_g=0.0003))
    assert record.predicted_tilt_error_deg == 0.05 and record.notes == ()


def test_attitude_command_reports_the_raised_error(tmp_path, capsys):
    """`accelcal attitude` says on stderr that the file's uncertainty was raised."""
    from accelcal_ros.cli import main
    from accelcal_ros.sensor.recording import save_recording

    cal = _calibration_file(tmp_path, predicted_tilt_error_deg=0.001, holdout_rms_g=0.01)
    rec = str(tmp_path / 'rec.csv')
    save_recording(rec, np.arange(50) * 0.01, np.tile([0.0, 0.0, 9.80665], (50, 1)))
    assert main(['attitude', '--calibration', cal, rec]) == 0
    err = capsys.readouterr().err
    assert 'predicted roll/pitch error raised' in err


@pytest.fixture(scope='module')
def protocol_positions():
    """Paper B's 15 simulated static positions (seed 7)."""
    return sim.positions_for_calibration(sim.simulate_protocol(sim.default_boresight(),
                                                               seed=7))


def test_boresight_std_not_below_the_half_fits_disagreement(protocol_positions):
    """Odd positions' gravity tilted 0.6 deg: the halves disagree, the sigma says so."""
    tilt = Rotation.from_rotvec(np.radians([0.6, 0.0, 0.0])).as_matrix()
    bad = [dataclasses.replace(p, gravity_m_s2=tilt @ np.asarray(p.gravity_m_s2)) if k % 2
           else p for k, p in enumerate(protocol_positions)]
    res = calibrate_boresight(bad, sim.nominal_mount())
    known = res.holdout['even_vs_odd_rotation'] / (2 * HALVES_95)
    cov, _ = rotation_covariance(res.rotation, res.normals, res.gravity, res.weights)
    assert np.all(rpy_std_deg(res.rotation, cov) < known)  # the case this test is about
    assert np.all(res.rpy_std_deg >= known - 1e-12)
    assert np.all(np.sqrt(np.diag(res.covariance_rad2)) >= np.sqrt(np.diag(cov)))
    assert any('half fits' in w and 'raised' in w for w in res.warnings)


def test_boresight_normal_case_unchanged(protocol_positions):
    """The undisturbed protocol: the sigma is the covariance's, no note."""
    res = calibrate_boresight(protocol_positions, sim.nominal_mount())
    cov, _ = rotation_covariance(res.rotation, res.normals, res.gravity, res.weights)
    np.testing.assert_allclose(res.rpy_std_deg, rpy_std_deg(res.rotation, cov))
    assert not any('raised' in w for w in res.warnings)


def test_boresight_at_the_search_limit_claims_no_better_than_its_distance():
    """A result 14 deg from the prior, at the floor search's cone: sigma >= 14 deg."""
    cov = np.diag([1e-8, 1e-8, 1e-8])
    warn = []
    std, new_cov = _honest_std(np.eye(3), cov, {'even_vs_odd_rotation': 0.001}, 14.0, warn)
    assert np.all(std >= 14.0) and 'search limit' in warn[0]
    assert np.all(np.degrees(np.sqrt(np.diag(new_cov))) >= 13.9)
