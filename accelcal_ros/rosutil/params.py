"""
Declare parameters from :class:`~accelcal_ros.paramspec.ParamSpec` lists.

Each parameter gets a ``ParameterDescriptor`` with its description, its numeric range
(when it has one) and its other constraints as text, so ``ros2 param describe`` shows
them. Values are validated at start-up (a bad value is an error naming the parameter and
the reason) and at run time through a set-parameters callback that rejects bad values
with the reason.
"""
from accelcal_ros.errors import InputError
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType, SetParametersResult)
from rclpy.parameter import Parameter

_TYPES = {
    'bool': ParameterType.PARAMETER_BOOL,
    'int': ParameterType.PARAMETER_INTEGER,
    'double': ParameterType.PARAMETER_DOUBLE,
    'string': ParameterType.PARAMETER_STRING,
    'double_array': ParameterType.PARAMETER_DOUBLE_ARRAY,
    'int_array': ParameterType.PARAMETER_INTEGER_ARRAY,
    'string_array': ParameterType.PARAMETER_STRING_ARRAY,
}

_EMPTY_TYPES = {
    'double_array': Parameter.Type.DOUBLE_ARRAY,
    'int_array': Parameter.Type.INTEGER_ARRAY,
    'string_array': Parameter.Type.STRING_ARRAY,
}


def descriptor_for(spec):
    """Build the ParameterDescriptor of one spec."""
    descriptor = ParameterDescriptor(
        name=spec.name, type=_TYPES[spec.kind], description=spec.description,
        additional_constraints=spec.constraints_text(), read_only=spec.read_only,
        # ints are accepted for doubles (``-p fov:=180``); ParamSpec.check enforces kinds.
        # (not for empty-list defaults, which must be declared by type instead)
        dynamic_typing=(spec.kind == 'double'
                        or (spec.kind == 'double_array' and bool(spec.default))))
    if spec.kind in ('double', 'double_array') and spec.minimum is not None \
            and spec.maximum is not None:
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(spec.minimum), to_value=float(spec.maximum), step=0.0)]
    if spec.kind in ('int', 'int_array') and spec.minimum is not None \
            and spec.maximum is not None:
        descriptor.integer_range = [IntegerRange(
            from_value=int(spec.minimum), to_value=int(spec.maximum), step=0)]
    return descriptor


class ParameterSet:
    """
    The validated parameter values of a node, kept current by the set callback.

    ``on_change(name, value)`` (optional) is called after a run-time change was accepted;
    it may raise :class:`InputError` to reject the change with its message.
    """

    def __init__(self, node, specs, on_change=None):
        self._node = node
        self._specs = {s.name: s for s in specs}
        self._on_change = on_change
        self.values = {}
        reasons = []
        for spec in specs:
            if spec.kind.endswith('_array') and not spec.default:
                # an empty list has no type: declare by type (value stays unset if not given)
                param = node.declare_parameter(spec.name, _EMPTY_TYPES[spec.kind],
                                               descriptor_for(spec))
                raw = param.value if param.value is not None else []
            else:
                param = node.declare_parameter(spec.name, spec.default, descriptor_for(spec))
                raw = param.value
            value, reason = spec.check(raw)
            if reason:
                reasons.append(reason)
            else:
                self.values[spec.name] = value
        if reasons:
            raise InputError('invalid parameter value(s): ' + '; '.join(reasons))
        node.add_on_set_parameters_callback(self._on_set)

    def __getitem__(self, name):
        """Return the current value of parameter ``name``."""
        return self.values[name]

    def _on_set(self, params):
        accepted = {}
        for param in params:
            spec = self._specs.get(param.name)
            if spec is None:
                continue
            value, reason = spec.check(param.value if param.value is not None else [])
            if reason:
                self._node.get_logger().warning(f'rejected parameter change: {reason}')
                return SetParametersResult(successful=False, reason=reason)
            accepted[param.name] = value
        if self._on_change is not None:
            for name, value in accepted.items():
                try:
                    self._on_change(name, value)
                except InputError as exc:
                    reason = f'{name}: {exc}'
                    self._node.get_logger().warning(f'rejected parameter change: {reason}')
                    return SetParametersResult(successful=False, reason=reason)
        self.values.update(accepted)
        return SetParametersResult(successful=True)
