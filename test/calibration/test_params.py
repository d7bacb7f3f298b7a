"""Node parameters: config files list every parameter with its default; bad values rejected."""
import os

from accelcal_ros.attitude.params import ATTITUDE_PARAMS
from accelcal_ros.calibration.params import CALIBRATION_PARAMS, calibrator_config
from accelcal_ros.paramspec import check_all
import pytest
import yaml

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.mark.parametrize('node, specs', [('calibration', CALIBRATION_PARAMS),
                                         ('attitude', ATTITUDE_PARAMS)])
def test_config_file_has_every_parameter_and_its_default(node, specs):
    with open(os.path.join(REPO, 'config', f'{node}.yaml')) as handle:
        values = yaml.safe_load(handle)[node]['ros__parameters']
    for spec in specs:
        if spec.kind.endswith('_array') and not spec.default:
            continue  # empty arrays cannot be typed in a params file: left commented
        assert spec.name in values, spec.name
        assert values[spec.name] == spec.default, spec.name
    assert not set(values) - {s.name for s in specs}


def test_defaults_valid_and_bad_values_rejected_with_reason():
    defaults = {s.name: s.default for s in CALIBRATION_PARAMS}
    _, reasons = check_all(CALIBRATION_PARAMS, defaults)
    assert not reasons
    assert calibrator_config(defaults).model == 'full'
    _, reasons = check_all(CALIBRATION_PARAMS, {'model': 'cubic', 'min_still_s': 0.0})
    assert len(reasons) == 2 and any('one of' in r for r in reasons)
    _, reasons = check_all(ATTITUDE_PARAMS, {'calibration.scale': [1.0, 1.0],
                                             'calibration.bias': [0.0, float('nan'), 0.0],
                                             'noise_std_g': [0.1]})
    assert len(reasons) == 3
