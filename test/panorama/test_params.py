"""Stitcher parameters: defaults, validation, and config/stitcher.yaml listing them all."""
import os

from accelcal_ros.panorama.params import STITCHER_PARAMS
from accelcal_ros.panorama.roi_params import STITCHER_WITH_ROI_PARAMS
from accelcal_ros.paramspec import check_all
from accelcal_ros.textformats import load_yaml_mapping
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_config_file_lists_every_parameter_with_its_default():
    """config/stitcher.yaml has every parameter, with the spec's default value."""
    data = load_yaml_mapping(os.path.join(ROOT, 'config', 'stitcher.yaml'))
    values = data['stitcher']['ros__parameters']
    assert set(values) == {s.name for s in STITCHER_WITH_ROI_PARAMS}  # the views' too
    for spec in STITCHER_WITH_ROI_PARAMS:
        assert values[spec.name] == pytest.approx(spec.default) if spec.kind in (
            'double', 'double_array') else values[spec.name] == spec.default


@pytest.mark.parametrize('name, value, words', [
    ('imu_to_camera', [1, 0, 0, 0, 1, 0, 0, 0, 2], 'not a rotation'),
    ('imu_to_camera', [1, 0, 0], 'expected 9 values'), ('projection', 'fisheye', 'one of'),
    ('grid_step', 15, 'even'), ('fov_v_deg', 200.0, 'maximum'),
    ('sync_tolerance_s', float('nan'), 'finite'), ('output_encoding', 'rgba8', 'one of')])
def test_bad_values_are_rejected_with_the_reason(name, value, words):
    """ParamSpec.check names the parameter and the reason."""
    _, reasons = check_all(STITCHER_PARAMS, {name: value})
    assert len(reasons) == 1 and name in reasons[0] and words in reasons[0]
