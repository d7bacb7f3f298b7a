"""Parameter typing and executor choice without a graph (the graph tests run the nodes)."""
from accelcal_ros.errors import AccelcalError
from accelcal_ros.paramspec import ParamSpec
from accelcal_ros.rosutil.params import coerce_parameters, descriptor_for, PARAMETER_TYPES
from accelcal_ros.rosutil.runner import executor_kind
import pytest
from rcl_interfaces.msg import ParameterType
from rclpy.parameter import Parameter

SPECS = {s.name: s for s in (
    ParamSpec('scale', [1.0, 1.0, 1.0], 'k', lengths=(3,), minimum=0.1, maximum=10.0),
    ParamSpec('time_constant_s', 0.0, 't', minimum=0.0, maximum=60.0),
    ParamSpec('poses', [], 'p', kind='double_array'),
    ParamSpec('names', [], 'n', kind='string_array'),
    ParamSpec('bus', 1, 'b', minimum=0, maximum=255),
)}


def test_numbers_are_coerced_to_the_declared_type():
    """Integers become doubles, empty lists get the declared array type."""
    given = [Parameter('scale', value=[1, 2, 1]), Parameter('time_constant_s', value=2),
             Parameter('poses', value=[]), Parameter('names', value=[]),
             Parameter('bus', value=3)]
    out = {p.name: p for p in coerce_parameters(SPECS, given)}
    assert out['scale'].type_ == Parameter.Type.DOUBLE_ARRAY
    assert out['scale'].value == [1.0, 2.0, 1.0]
    assert (out['time_constant_s'].type_, out['time_constant_s'].value) == \
        (Parameter.Type.DOUBLE, 2.0)
    assert out['poses'].type_ == Parameter.Type.DOUBLE_ARRAY
    assert out['names'].type_ == Parameter.Type.STRING_ARRAY
    assert out['bus'].type_ == Parameter.Type.INTEGER


def test_what_cannot_be_coerced_is_left_for_the_static_type_check():
    """A string for a double or a double for an integer passes unchanged (rclpy refuses)."""
    given = [Parameter('time_constant_s', value='fast'), Parameter('bus', value=2.5),
             Parameter('undeclared', value=1)]
    out = coerce_parameters(SPECS, given)
    assert [(p.name, p.type_) for p in out] == [
        ('time_constant_s', Parameter.Type.STRING), ('bus', Parameter.Type.DOUBLE),
        ('undeclared', Parameter.Type.INTEGER)]


def test_descriptors_are_statically_typed_with_ranges():
    """No dynamic typing: a parameter keeps its declared type."""
    for spec in SPECS.values():
        descriptor = descriptor_for(spec)
        assert not descriptor.dynamic_typing
        assert descriptor.type == PARAMETER_TYPES[spec.kind].value
    assert descriptor_for(SPECS['bus']).integer_range[0].to_value == 255
    assert descriptor_for(SPECS['scale']).type == ParameterType.PARAMETER_DOUBLE_ARRAY


def test_executor_choice_from_the_environment():
    """ACCELCAL_EXECUTOR overrides the node default; a misspelt value is one clear error."""
    assert executor_kind('events', {}) == 'events'
    assert executor_kind('events', {'ACCELCAL_EXECUTOR': ' Single '}) == 'single'
    assert executor_kind('single', {'ACCELCAL_EXECUTOR': ''}) == 'single'
    with pytest.raises(AccelcalError, match='use one of events, single, multi'):
        executor_kind('events', {'ACCELCAL_EXECUTOR': 'fast'})
