"""
Declarative schemas of the package's YAML and CSV inputs (shared floor).

Every YAML file the package reads is checked against a :data:`Schema` (key ->
:class:`Key`: what the value must be, a check, required or not; a nested mapping has its
own schema) by :func:`check_mapping`: an unknown key, a missing required key or a value of
the wrong type is refused with one line naming the key (``camera_matrix.rows``). Every CSV
the package reads is a :class:`CsvFormat` (required and optional columns);
:func:`accelcal_ros.textformats.read_numeric_csv` refuses any other column. The formats
are listed in ``docs/formats.md``; :data:`CSV_FORMATS` is the one list of CSV formats.
"""
from dataclasses import dataclass
import math
from typing import Any, Callable, Dict, Mapping, Optional, Tuple

from accelcal_ros.errors import InputError, listed

Check = Callable[[Any], bool]


@dataclass(frozen=True)
class Key:
    """One key of a YAML mapping: ``what`` it must be (for the error), its check."""

    what: str
    check: Optional[Check] = None
    required: bool = False
    schema: Optional[Mapping[str, 'Key']] = None  # a nested mapping


Schema = Mapping[str, Key]


def number_value(value: Any) -> Optional[float]:
    """Return a YAML scalar as a float when it is a number (bools are not), else None."""
    from accelcal_ros.textformats import yaml_number

    return yaml_number(value)


def is_number(value: Any) -> bool:
    """Whether ``value`` is a finite number (``true`` is not 1.0)."""
    number = number_value(value)
    return number is not None and math.isfinite(number)


def is_real(value: Any) -> bool:
    """Whether ``value`` is a number, NaN and infinity included (a reported figure)."""
    return number_value(value) is not None


def is_integer(value: Any) -> bool:
    """Whether ``value`` is an integer (not a bool, not 3.0)."""
    return isinstance(value, int) and not isinstance(value, bool)


def is_text(value: Any) -> bool:
    """Whether ``value`` is a string."""
    return isinstance(value, str)


def is_bool(value: Any) -> bool:
    """Whether ``value`` is true or false."""
    return isinstance(value, bool)


def numbers(count: Optional[int] = None, finite: bool = True) -> Check:
    """Return a check for a list of ``count`` (any count if None) (finite) numbers."""
    item = is_number if finite else is_real

    def check(value: Any) -> bool:
        return (isinstance(value, list) and (count is None or len(value) == count)
                and all(item(v) for v in value))
    return check


def list_of(item: Check) -> Check:
    """Return a check for a list whose every item passes ``item``."""
    return lambda value: isinstance(value, list) and all(item(v) for v in value)


def number_rows(width: int, finite: bool = True) -> Check:
    """Return a check for a list of lists of ``width`` (finite) numbers."""
    row = numbers(width, finite)
    return lambda value: isinstance(value, list) and all(row(v) for v in value)


def or_none(check: Check) -> Check:
    """Return ``check`` that also lets ``null`` through."""
    return lambda value: value is None or check(value)


def one_of(*choices: Any) -> Check:
    """Return a check for one of ``choices`` (compared with ==, bools excluded)."""
    return lambda value: not isinstance(value, bool) and value in choices


def anything(value: Any) -> bool:
    """Accept any value (a free-form field such as a comment)."""
    return True


def text_mapping(value: Any) -> bool:
    """Accept a mapping of text keys (free-form values)."""
    return isinstance(value, dict) and all(isinstance(k, str) for k in value)


def check_mapping(data: Any, schema: Schema, what: str, where: str = '') -> None:
    """
    Check a parsed YAML mapping against ``schema``; InputError naming the key otherwise.

    Unknown keys are refused (a misspelt key would otherwise read as its default), required
    keys must be present and not null, every present value must pass its check (a nested
    mapping is checked key by key, its keys named ``parent.child``).
    """
    if not isinstance(data, Mapping):
        name = where.rstrip('.') or what
        raise InputError(f'{name} must be a mapping, got {type(data).__name__}')
    unknown = sorted(str(k) for k in data if k not in schema)
    missing = [where + k for k, key in schema.items()
               if key.required and data.get(k) is None]
    if missing and unknown:
        raise InputError(f'missing key(s) {", ".join(missing)} and unknown key(s) '
                         f'{listed([where + k for k in unknown])} in {what} (misspelt?)')
    if unknown:
        raise InputError(f'unknown key(s) {listed([where + k for k in unknown])}; {what} '
                         f'holds only {", ".join(where + k for k in schema)} (misspelt?)')
    if missing:
        raise InputError(f'missing key(s) {", ".join(missing)} ({what}; truncated file?)')
    for name, key in schema.items():
        if name not in data or data[name] is None and not key.required:
            continue
        value = data[name]
        if key.schema is not None:
            check_mapping(value, key.schema, what, f'{where}{name}.')
        elif key.check is not None and not key.check(value):
            shown = repr(value)
            shown = shown if len(shown) <= 80 else shown[:77] + '...'
            raise InputError(f'"{where}{name}" must be {key.what}, got {shown}')


def schema_table(schema: Schema, where: str = '') -> Tuple[Tuple[str, str, str], ...]:
    """Return ``(key, required, what)`` rows of a schema (nested keys dotted), for docs."""
    rows = []
    for name, key in schema.items():
        rows.append((where + name, 'yes' if key.required else 'no', key.what))
        if key.schema is not None:
            rows.extend(schema_table(key.schema, f'{where}{name}.'))
    return tuple(rows)


@dataclass(frozen=True)
class CsvFormat:
    """A numeric CSV: a header naming ``required`` and optionally ``optional`` columns."""

    name: str
    required: Tuple[str, ...]
    optional: Tuple[str, ...] = ()

    @property
    def columns(self) -> Tuple[str, ...]:
        """Every column the format may hold."""
        return self.required + self.optional


RECORDING_CSV = CsvFormat('IMU recording', ('t', 'ax', 'ay', 'az'), ('gx', 'gy', 'gz'))
"""``accelcal record``/``save_recording`` and the LiDAR positions' ``*_imu.csv``: time (s),
specific force (m/s^2), optionally angular rate (rad/s)."""
ODOMETRY_CSV = CsvFormat('odometry', ('t', 'v', 'yaw_rate'))
"""Wheel odometry for ``accelcal attitude --odometry``: s, m/s, rad/s."""
POSES_CSV = CsvFormat('poses', ('t', 'x', 'y', 'z', 'qx', 'qy', 'qz', 'qw'))
"""Platform poses for ``accelcal georeference``: s, m, unit quaternion (x, y, z, w)."""
TRAJECTORY_CSV = CsvFormat('geodetic trajectory', ('t', 'lat', 'lon', 'h', 'roll', 'pitch',
                                                   'yaw'))
"""A geodetic trajectory: s, deg, deg, m (ellipsoidal), deg (REP-103 roll, pitch, yaw)."""
VIEW_PATH_CSV = CsvFormat('view path', ('t', 'azimuth', 'elevation', 'fov_h'))
"""A levelled view's path for ``accelcal view --path``: s, deg, deg, deg."""

CSV_FORMATS: Dict[str, CsvFormat] = {f.name: f for f in (
    RECORDING_CSV, ODOMETRY_CSV, POSES_CSV, TRAJECTORY_CSV, VIEW_PATH_CSV)}
"""Every CSV format the package reads."""


__all__ = ['check_mapping', 'CSV_FORMATS', 'CsvFormat', 'is_bool', 'is_integer', 'is_number',
           'is_real', 'is_text', 'Key', 'list_of', 'number_rows', 'numbers', 'one_of',
           'or_none', 'Schema', 'schema_table', 'text_mapping']
