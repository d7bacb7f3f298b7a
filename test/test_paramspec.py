"""Parameter specifications: coercion, ranges, choices, lengths and reasons."""
from accelcal_ros.paramspec import check_all, ParamSpec
import pytest


def test_numbers_ranges_and_choices():
    """Ints are accepted for doubles; out-of-range and unlisted values get a reason."""
    rate = ParamSpec('rate_hz', 100.0, 'rate', choices=(100.0, 800.0))
    assert rate.check(800) == (800.0, None)
    value, reason = rate.check(123.0)
    assert value is None and 'rate_hz: 123.0 is not one of 100.0, 800.0' == reason
    dwell = ParamSpec('dwell_s', 1.0, 'dwell', minimum=0.1, maximum=5.0, unit='s')
    assert 'below the minimum' in dwell.check(0.0)[1]
    assert 'above the maximum' in dwell.check(9.0)[1]
    assert 'not a finite number' in dwell.check(float('nan'))[1]
    assert 'expected a number' in dwell.check('fast')[1]
    assert dwell.constraints_text() == 'unit: s; range [0.1, 5]'


def test_arrays_and_validators():
    """Array lengths, per-element bounds and custom validators."""
    scale = ParamSpec('scale', [1.0, 1.0, 1.0], 'k', lengths=(3,), minimum=0.1)
    assert scale.check([1, 2, 3]) == ([1.0, 2.0, 3.0], None)
    assert 'expected 3 values, got 2' in scale.check([1.0, 2.0])[1]
    assert 'below the minimum' in scale.check([1.0, 0.0, 1.0])[1]
    name = ParamSpec('frame_id', 'imu', 'frame',
                     validator=lambda v: None if v else 'must not be empty')
    assert name.check('')[1] == 'frame_id: must not be empty'
    assert ParamSpec('poses', [], 'p', kind='double_array').check([]) == ([], None)
    with pytest.raises(ValueError, match='give kind'):
        ParamSpec('poses', [], 'p')
    values, reasons = check_all([scale, name], {'scale': [1, 1, 1], 'frame_id': '',
                                                'other': 3})
    assert values == {'scale': [1.0, 1.0, 1.0]} and reasons == ['frame_id: must not be empty']
    assert ParamSpec('flag', True, 'f').check(1)[1] == 'flag: expected true or false, got 1'
