"""
Declare parameters from :class:`~accelcal_ros.paramspec.ParamSpec` lists.

Each parameter gets a ``ParameterDescriptor`` with its description, its numeric range
(when it has one) and its other constraints as text, so ``ros2 param describe`` shows
them. Rules, so that ``ros2 param dump/get/set`` see what the specs say:

- Every parameter is declared with a value (its override or its default), empty arrays
  included: rclpy's GetParameters answers nothing for a whole request that names one
  parameter without a value (``ros2 param dump`` printed ``{}``).
- Types are static: a number set at start-up (``-p fov_h_deg:=180``) or at run time
  (``ros2 param set ... time_constant_s 2``, ``calibration.scale "[1, 1, 1]"``) is
  coerced to the declared type (integers to doubles), anything else is refused; a
  parameter never changes type.
- Values are validated at start-up (every bad value is named in one :class:`InputError`
  line, before rclpy's own range check can raise) and at run time by a set-parameters
  callback that rejects a bad value with the reason.
- A request is all or nothing: when ``on_change`` rejects one parameter of a
  SetParametersAtomically request, the changes it already applied for the earlier ones
  are undone (``on_change`` is called again with their previous values, in reverse
  order), and rclpy stores none of them.
"""
from typing import Any, Callable, Dict, Iterable, List, Optional, Tuple

from accelcal_ros.errors import InputError
from accelcal_ros.paramspec import ParamSpec
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType, SetParametersResult)
from rclpy.exceptions import ParameterException
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

PARAMETER_TYPES = {
    'bool': Parameter.Type.BOOL,
    'int': Parameter.Type.INTEGER,
    'double': Parameter.Type.DOUBLE,
    'string': Parameter.Type.STRING,
    'double_array': Parameter.Type.DOUBLE_ARRAY,
    'int_array': Parameter.Type.INTEGER_ARRAY,
    'string_array': Parameter.Type.STRING_ARRAY,
}
"""rclpy parameter type of each ParamSpec kind."""


def descriptor_for(spec: ParamSpec) -> ParameterDescriptor:
    """Build the (statically typed) ParameterDescriptor of one spec."""
    descriptor = ParameterDescriptor(
        name=spec.name, type=_TYPES[spec.kind], description=spec.description,
        additional_constraints=spec.constraints_text(), read_only=spec.read_only,
        dynamic_typing=False)
    if spec.kind in ('double', 'double_array') and spec.minimum is not None \
            and spec.maximum is not None:
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(spec.minimum), to_value=float(spec.maximum), step=0.0)]
    if spec.kind in ('int', 'int_array') and spec.minimum is not None \
            and spec.maximum is not None:
        descriptor.integer_range = [IntegerRange(
            from_value=int(spec.minimum), to_value=int(spec.maximum), step=0)]
    return descriptor


def typed_parameter(spec: ParamSpec, value: Any) -> Parameter:
    """``Parameter`` of ``value`` (already coerced by the spec) with the spec's type."""
    return Parameter(spec.name, PARAMETER_TYPES[spec.kind], value)


def coerce_parameters(specs: Dict[str, ParamSpec], params: Iterable[Parameter]
                      ) -> List[Parameter]:
    """
    Parameters with numbers converted to their spec's type (ints to doubles, [] typed).

    A value the spec cannot coerce is passed on unchanged: rclpy's static type check then
    refuses it with the expected type.
    """
    out = []
    for param in params:
        spec = specs.get(param.name)
        if spec is not None and param.type_ != Parameter.Type.NOT_SET:
            try:
                value = spec.coerce(param.value)
            except TypeError:
                pass
            else:
                param = typed_parameter(spec, value)
        out.append(param)
    return out


def _override(node, name: str) -> Tuple[bool, Any]:
    """Return ``(True, value)`` of a ``-p``/params-file override, else ``(False, None)``."""
    overrides = getattr(node, '_parameter_overrides', None) or {}
    param = overrides.get(name)
    if param is None or param.type_ == Parameter.Type.NOT_SET:
        return False, None
    return True, param.value


def declare_spec(node, spec: ParamSpec) -> Tuple[Any, Optional[str]]:
    """
    Declare one parameter with its override (coerced) or default; ``(value, reason)``.

    A bad override is not declared: ``(None, reason)``. An empty array is declared by
    type and then given its typed empty value (rclpy infers no type from ``[]``), the
    read-only flag applied after that through ``set_descriptor``.
    """
    given, raw = _override(node, spec.name)
    value, reason = spec.check(raw if given else spec.default)
    if reason:
        return None, reason + (' (given at start-up)' if given else ' (default)')
    descriptor = descriptor_for(spec)
    try:
        if isinstance(value, list) and not value:
            writable = descriptor_for(spec)
            writable.read_only = False
            node.declare_parameter(spec.name, PARAMETER_TYPES[spec.kind], writable,
                                   ignore_override=True)
            node.set_parameters([typed_parameter(spec, [])])
            if spec.read_only:
                node.set_descriptor(spec.name, descriptor)
        else:
            node.declare_parameter(spec.name, value, descriptor, ignore_override=True)
    except ParameterException as exc:
        return None, f'{spec.name}: {exc}'
    return value, None


class ParameterSet:
    """
    The validated parameter values of a node, kept current by the set callback.

    ``on_change(name, value)`` (optional) is called after a run-time change was accepted;
    it may raise :class:`InputError` to reject the change with its message. It must also
    accept a parameter's previous value again: that is how a rejected request's earlier
    changes are undone.
    """

    def __init__(self, node, specs: Iterable[ParamSpec],
                 on_change: Optional[Callable[[str, Any], None]] = None) -> None:
        specs = list(specs)
        self._node = node
        self._specs = {s.name: s for s in specs}
        self._on_change = on_change
        self.values: Dict[str, Any] = {}
        reasons = []
        for spec in specs:
            value, reason = declare_spec(node, spec)
            if reason:
                reasons.append(reason)
            else:
                self.values[spec.name] = value
        if reasons:
            raise InputError('invalid parameter value(s): ' + '; '.join(reasons))
        if hasattr(node, 'add_pre_set_parameters_callback'):
            node.add_pre_set_parameters_callback(self._coerce)
        node.add_on_set_parameters_callback(self._on_set)

    def __getitem__(self, name: str) -> Any:
        """Return the current value of parameter ``name``."""
        return self.values[name]

    def _coerce(self, params: List[Parameter]) -> List[Parameter]:
        return coerce_parameters(self._specs, params)

    def _reject(self, reason: str) -> SetParametersResult:
        self._node.get_logger().warning(f'rejected parameter change: {reason}')
        return SetParametersResult(successful=False, reason=reason)

    def _on_set(self, params: List[Parameter]) -> SetParametersResult:
        accepted = {}
        for param in params:
            spec = self._specs.get(param.name)
            if spec is None:
                continue
            value, reason = spec.check(param.value if param.value is not None else [])
            if reason:
                return self._reject(reason)
            accepted[param.name] = value
        if self._on_change is not None:
            applied = []
            for name, value in accepted.items():
                try:
                    self._on_change(name, value)
                except InputError as exc:
                    self._undo(applied)
                    return self._reject(f'{name}: {exc}; nothing of this request was '
                                        'applied')
                applied.append(name)
        self.values.update(accepted)
        return SetParametersResult(successful=True)

    def _undo(self, names: List[str]) -> None:
        for name in reversed(names):
            try:
                self._on_change(name, self.values[name])
            except InputError as exc:  # the previous value was accepted once: unexpected
                self._node.get_logger().error(f'could not restore {name}: {exc}')
