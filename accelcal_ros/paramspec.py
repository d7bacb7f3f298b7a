"""
Parameter specifications: name, default, description, range and validation, without rclpy.

Nodes list their parameters as :class:`ParamSpec` objects; :mod:`accelcal_ros.rosutil.params`
turns each into a declared ROS parameter with a descriptor (description, range) and a
set-parameters callback that rejects a bad value with the reason from :meth:`ParamSpec.check`.
Keeping the rules here lets tests check them without a ROS graph.
"""
from dataclasses import dataclass
import math
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

_KINDS = ('bool', 'int', 'double', 'string', 'double_array', 'int_array', 'string_array')


@dataclass(frozen=True)
class ParamSpec:
    """
    One node parameter.

    ``kind`` is one of ``bool, int, double, string, double_array, int_array,
    string_array``. ``minimum``/``maximum`` bound numbers (each element of an array);
    ``choices`` lists allowed values; ``length`` fixes an array's length (or ``lengths``
    gives allowed lengths); ``validator(value)`` returns a reason string when the value is
    bad. ``read_only`` parameters can only be set at start-up.
    """

    name: str
    default: Any
    description: str
    kind: str = ''
    minimum: Optional[float] = None
    maximum: Optional[float] = None
    choices: Optional[Sequence[Any]] = None
    lengths: Optional[Sequence[int]] = None
    validator: Optional[Callable[[Any], Optional[str]]] = None
    read_only: bool = False
    unit: str = ''

    def __post_init__(self) -> None:
        """Infer ``kind`` from the default when not given."""
        if not self.kind:
            object.__setattr__(self, 'kind', infer_kind(self.default))
        if self.kind not in _KINDS:
            raise ValueError(f'parameter {self.name}: unknown kind {self.kind!r}')

    def constraints_text(self) -> str:
        """Human-readable constraints, shown in the descriptor's additional_constraints."""
        parts = []
        if self.unit:
            parts.append(f'unit: {self.unit}')
        if self.minimum is not None or self.maximum is not None:
            lo = '-inf' if self.minimum is None else f'{self.minimum:g}'
            hi = 'inf' if self.maximum is None else f'{self.maximum:g}'
            parts.append(f'range [{lo}, {hi}]')
        if self.choices is not None:
            parts.append('one of ' + ', '.join(str(c) for c in self.choices))
        if self.lengths is not None:
            parts.append('length ' + ' or '.join(str(n) for n in self.lengths))
        return '; '.join(parts)

    def coerce(self, value: Any) -> Any:
        """Value converted to the spec's kind (ints accepted for doubles); TypeError if not."""
        kind = self.kind
        if kind == 'double':
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise TypeError(f'expected a number, got {value!r}')
            return float(value)
        if kind == 'int':
            if isinstance(value, bool) or not isinstance(value, int):
                raise TypeError(f'expected an integer, got {value!r}')
            return int(value)
        if kind == 'bool':
            if not isinstance(value, bool):
                raise TypeError(f'expected true or false, got {value!r}')
            return value
        if kind == 'string':
            if not isinstance(value, str):
                raise TypeError(f'expected a string, got {value!r}')
            return value
        if not isinstance(value, (list, tuple)) and not hasattr(value, 'tolist'):
            raise TypeError(f'expected a list, got {value!r}')
        items = list(value.tolist() if hasattr(value, 'tolist') else value)
        element = ParamSpec(self.name, None, '', kind=kind.split('_')[0])
        return [element.coerce(v) for v in items]

    def check(self, value: Any) -> Tuple[Any, Optional[str]]:
        """Return ``(coerced_value, None)`` or ``(None, reason)`` for a proposed value."""
        try:
            coerced = self.coerce(value)
        except TypeError as exc:
            return None, f'{self.name}: {exc}'
        items = coerced if isinstance(coerced, list) else [coerced]
        if self.lengths is not None and isinstance(coerced, list) \
                and len(coerced) not in self.lengths:
            allowed = ' or '.join(str(n) for n in self.lengths)
            return None, f'{self.name}: expected {allowed} values, got {len(coerced)}'
        for item in items:
            if isinstance(item, float) and not math.isfinite(item):
                return None, f'{self.name}: {item} is not a finite number'
            if self.minimum is not None and item < self.minimum:
                return None, f'{self.name}: {item} is below the minimum {self.minimum:g}'
            if self.maximum is not None and item > self.maximum:
                return None, f'{self.name}: {item} is above the maximum {self.maximum:g}'
        if self.choices is not None and coerced not in self.choices:
            allowed = ', '.join(str(c) for c in self.choices)
            return None, f'{self.name}: {coerced!r} is not one of {allowed}'
        if self.validator is not None:
            reason = self.validator(coerced)
            if reason:
                return None, f'{self.name}: {reason}'
        return coerced, None


def output_file_check(allow_empty: bool = False) -> Callable[[Any], Optional[str]]:
    """
    Return a ``validator`` for an output-file parameter.

    Refuses an empty value (unless ``allow_empty``: empty then means "no file"), an
    existing directory and anything that is not a regular file (``/dev/full``, a FIFO),
    with :func:`accelcal_ros.filecheck.existing_output_problem`'s reason.
    """
    from accelcal_ros.filecheck import existing_output_problem

    def check(value: Any) -> Optional[str]:
        if allow_empty and not str(value).strip():
            return None
        if not str(value).strip():
            return 'must not be empty: give the path of the file to write'
        return existing_output_problem(str(value))
    return check


def infer_kind(default: Any) -> str:
    """Parameter kind from a default value (empty lists need an explicit kind)."""
    if isinstance(default, bool):
        return 'bool'
    if isinstance(default, int):
        return 'int'
    if isinstance(default, float):
        return 'double'
    if isinstance(default, str):
        return 'string'
    if isinstance(default, (list, tuple)) and default:
        return infer_kind(default[0]) + '_array'
    raise ValueError(f'cannot infer a parameter kind from {default!r}; give kind=')


def check_all(specs: Iterable[ParamSpec], values: Mapping[str, Any]
              ) -> Tuple[Dict[str, Any], List[str]]:
    """Validate a ``{name: value}`` mapping; returns ``(coerced_dict, list_of_reasons)``."""
    by_name = {s.name: s for s in specs}
    out: Dict[str, Any] = {}
    reasons: List[str] = []
    for name, value in values.items():
        spec = by_name.get(name)
        if spec is None:
            continue
        coerced, reason = spec.check(value)
        if reason:
            reasons.append(reason)
        else:
            out[name] = coerced
    return out, reasons
