"""Calibration YAML: round trip, atomic write with backup, bad files."""
import os

from accelcal_ros.calibration.coverage import recommended_directions
from accelcal_ros.calibration.ellipsoid_fit import fit_ellipsoid
from accelcal_ros.errors import FileFormatError
from accelcal_ros.sensor.calibration_file import (load_calibration, load_sensor_model,
                                                  save_calibration)
from accelcal_ros.sensor.model import PAPER_K500_BIAS, PAPER_K500_SCALE, SensorModel
import numpy as np
import pytest
import yaml


@pytest.fixture
def result():
    truth = SensorModel(PAPER_K500_SCALE, PAPER_K500_BIAS, (0.004, -0.002, 0.003))
    raw = truth.distort(recommended_directions(14))
    raw += np.random.default_rng(0).normal(0.0, 3e-4, raw.shape)
    return fit_ellipsoid(raw, np.full((14, 3), 3e-4))


def test_round_trip_keys_and_equation(tmp_path, result):
    path = tmp_path / 'calib.yaml'
    save_calibration(path, result)
    data = yaml.safe_load(path.read_text())
    for key in ('model', 'scale', 'bias', 'misalignment', 'scale_std', 'bias_std',
                'residual_rms_g', 'positions', 'predicted_tilt_error_deg', 'equation'):
        assert key in data, key
    assert 'diag(1/scale)' in data['equation'] and 'atan2' in data['equation']
    model = load_sensor_model(path)
    np.testing.assert_allclose(model.scale, result.sensor_model.scale, atol=1e-8)
    np.testing.assert_allclose(model.bias, result.sensor_model.bias, atol=1e-8)
    np.testing.assert_allclose(model.misalignment, result.sensor_model.misalignment, atol=1e-8)
    record = load_calibration(path)
    assert record.model == 'full' and record.predicted_tilt_error_deg > 0


def test_equation_in_the_file_applies_without_the_package(tmp_path, result):
    path = tmp_path / 'calib.yaml'
    save_calibration(path, result)
    d = yaml.safe_load(path.read_text())
    m_yz, m_zy, m_zx = d['misalignment']
    t = np.array([[1, -m_yz, m_zy], [0, 1, -m_zx], [0, 0, 1]])
    raw = np.array([0.3, -0.5, 0.7])
    by_hand = t @ ((raw - np.array(d['bias'])) / np.array(d['scale']))
    np.testing.assert_allclose(by_hand, load_sensor_model(path).correct(raw), atol=1e-12)


def test_previous_file_kept_as_backup(tmp_path, result):
    path = tmp_path / 'calib.yaml'
    path.write_text('old: 1\n')
    save_calibration(path, result)
    assert (tmp_path / 'calib.yaml.bak').read_text() == 'old: 1\n'
    assert not [n for n in os.listdir(tmp_path) if n.startswith('.')]


@pytest.mark.parametrize('text, reason', [
    (None, 'not found'),
    ('', 'mapping'),
    ('model: diagonal\nscale: [0.9, 0.9, 0.9]\n', 'missing key "bias"'),
    ('model: diagonal\nscale: [0.9, 0.9]\nbias: [0, 0, 0]\n', '"scale" must be a list of 3'),
    ('model: diagonal\nscale: [0.9, 0.9, .nan]\nbias: [0, 0, 0]\n', 'NaN'),
    ('model: diagonal\nscale: [0.9, -0.9, 0.9]\nbias: [0, 0, 0]\n', '"scale" .* outside'),
    ('model: diagonal\nscale: [1e-300, 1, 1]\nbias: [0, 0, 0]\n', '"scale" .* outside'),
    ('model: diagonal\nscale: [1e300, 1, 1]\nbias: [0, 0, 0]\n', '"scale" .* outside'),
    ('model: diagonal\nscale: [1, 1, 1]\nbias: [0, 1e300, 0]\n', '"bias" .* outside'),
    ('model: full\nscale: [1, 1, 1]\nbias: [0, 0, 0]\nmisalignment: [0, 2, 0]\n',
     '"misalignment" .* outside'),
    ('model: diagonal\nscale: [1, 1, 1]\nbias: [0, 0, 0]\nbias_std: [.nan, 0, 0]\n',
     '"bias_std" contains NaN'),
    ('model: diagonal\nscale: [1, 1, 1]\nbias: [0, 0, 0]\npredicted_tilt_error_deg: -1\n',
     '"predicted_tilt_error_deg" .* outside'),
    ('model: diagonal\nscale: [1, 1, 1]\nbias: [0, 0, 0]\npredicted_tilt_error_deg: .inf\n',
     '"predicted_tilt_error_deg" .* outside'),
    ('model: diagonal\nscale: [0.9, 0.9, 0.9]\nbias: [a, b, c]\n', '"bias" must be'),
    ('model: cubic\nscale: [1, 1, 1]\nbias: [0, 0, 0]\n', 'one of'),
    ('model: diagonal\nscale: [0.9, 0.9, 0.9]\nbias: [0.1, 0.2', 'not valid YAML'),
])
def test_bad_files_raise_file_format_error(tmp_path, text, reason):
    path = tmp_path / 'calib.yaml'
    if text is not None:
        path.write_text(text)
    with pytest.raises(FileFormatError, match=reason) as info:
        load_sensor_model(path)
    assert str(path) in str(info.value)


def test_truncated_real_file_rejected(tmp_path, result):
    path = tmp_path / 'calib.yaml'
    save_calibration(path, result)
    text = path.read_text()
    path.write_text(text[:text.index('bias:') + 12])
    with pytest.raises(FileFormatError):
        load_sensor_model(path)


_GOOD = 'model: full\nscale: [1, 1, 1]\nbias: [0, 0, 0]\nmisalignment: [0, 0, 0]\n'


@pytest.mark.parametrize('text, reason', [
    ('model: full\nscale: [1, 1, 1]\nbias: [0, 0, 0]\n', 'missing key "misalignment"'),
    ('model: full\nscale: [true, true, true]\nbias: [0, 0, 0]\nmisalignment: [0, 0, 0]\n',
     '"scale" must be a list of 3 numbers'),
    (_GOOD.replace('bias: [0, 0, 0]', 'bias: [false, 0, 0]'), '"bias" must be a list of 3'),
    ('format: accelcal_ros/calibration 2\n' + _GOOD, 'unknown format'),
    ('format: 1\n' + _GOOD, '"format" must be'),
    (_GOOD + 'misalignement: [0.01, 0, 0]\n', 'unknown key.*misalignement'),
    (_GOOD + 'positions: true\n', '"positions" must be a non-negative integer'),
    (_GOOD + 'predicted_tilt_error_deg: yes\n', '"predicted_tilt_error_deg" must be'),
    (_GOOD + 'captures_g: [[1, 0]]\n', '"captures_g" must be'),
    ('scale: [1, 1, 1]\nbias: [0, 0, 0]\n', 'missing key "model"'),
    ('model: [full]\nscale: [1, 1, 1]\nbias: [0, 0, 0]\n', '"model" must be one of'),
    (_GOOD + 'residual_rms_g: 1e999999\nscale_std: [1, 1, 99999999999999999999999999]\n',
     None),
])
def test_schema_refuses_what_no_calibration_wrote(tmp_path, text, reason):
    """Required keys and types (issue 26): a full model without misalignment, bools..."""
    path = tmp_path / 'calib.yaml'
    path.write_text(text)
    if reason is None:  # a huge std is a type-correct value beyond the plausible range
        with pytest.raises(FileFormatError, match='outside the plausible range'):
            load_calibration(path)
        return
    with pytest.raises(FileFormatError, match=reason):
        load_calibration(path)


def test_diagonal_without_misalignment_and_the_written_keys_are_in_the_schema(tmp_path,
                                                                              result):
    """The diagonal model needs none; every key the writer writes is a schema key."""
    from accelcal_ros.sensor.calibration_file import calibration_dict, FORMAT, SCHEMA

    path = tmp_path / 'calib.yaml'
    path.write_text(f'format: {FORMAT}\nmodel: diagonal\nscale: [1, 1, 1]\nbias: [0, 0, 0]\n')
    assert load_calibration(path).model == 'diagonal'
    assert set(calibration_dict(result)) <= set(SCHEMA)
