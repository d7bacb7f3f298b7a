"""
The package's YAML and CSV text formats: read with clear errors, written in one style.

:func:`load_yaml_mapping` (a mapping at the top, no key twice, at most
:data:`MAX_YAML_SEPARATORS` separators before the parse and :data:`MAX_YAML_NODES` values
after aliases, no integer beyond a double), :func:`yaml_number` (a YAML scalar as a number:
bools are not numbers, YAML 1.2 exponents are), :func:`dump_yaml` (insertion order,
numeric lists in flow style) and :func:`read_numeric_csv` (a header, numbers only, errors
naming file and line). Every read
goes through :func:`accelcal_ros.fileio.read_input_text` (regular files only, size limits,
inputs guarded).
"""
import csv
import io
import math
import os
import re
import sys
from typing import Any, Dict, Optional, Sequence, TYPE_CHECKING

from accelcal_ros.errors import FileFormatError, listed, PathLike
from accelcal_ros.fileio import read_input_text
import yaml

if TYPE_CHECKING:  # numpy is imported where a CSV is read (keeps this module light)
    import numpy as np


#: PyYAML's C parser (libyaml) when built with it: the same safe constructor, about five
#: times faster than the pure-Python parser
_SafeLoaderBase = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)


class _DuplicateKey(Exception):
    """A mapping names a key twice (raised from inside the loader)."""

    def __init__(self, key: Any, line: int, first_line: int):
        super().__init__(key, line, first_line)
        self.key, self.line, self.first_line = key, line, first_line


class _StrictLoader(_SafeLoaderBase):  # type: ignore[valid-type, misc]
    """The safe loader that refuses a key given twice in one mapping (PyYAML keeps the last)."""

    def construct_mapping(self, node, deep=False):
        """Check the mapping's own keys for duplicates, then construct it as SafeLoader does."""
        if isinstance(node, yaml.MappingNode):
            seen: Dict[Any, int] = {}
            for key_node, _ in node.value:
                if key_node.tag == 'tag:yaml.org,2002:merge':
                    continue  # '<<: *base' merges; its keys may be overridden
                key = self.construct_object(key_node, deep=True)
                line = key_node.start_mark.line + 1
                try:
                    first = seen.get(key)
                except TypeError:
                    continue  # an unhashable key: the constructor refuses it
                if first is not None:
                    raise _DuplicateKey(key, line, first)
                seen[key] = line
        return super().construct_mapping(node, deep=deep)


def load_yaml_mapping(path: PathLike, what: str = 'file') -> Dict[Any, Any]:
    """
    Load a YAML file whose top level must be a mapping; raise FileFormatError otherwise.

    Refused with the line: invalid YAML, a key given twice in one mapping (PyYAML would keep
    the last silently), more than :data:`MAX_YAML_SEPARATORS` separators before parsing
    (bounds the parse time: about a second at the limit), more than :data:`MAX_YAML_NODES`
    values after aliases, an integer too large for a double (naming the key).
    """
    path = os.fspath(path)
    text = read_input_text(path, what, kind='yaml')
    separators = _separator_count(text)
    if separators > MAX_YAML_SEPARATORS:
        raise FileFormatError(path, f'{what} holds more than {MAX_YAML_SEPARATORS} YAML '
                              'separators (, : - ? [ { or line breaks); not a file this '
                              'package reads')
    try:
        data = yaml.load(text, Loader=_StrictLoader)  # noqa: S506 (a safe loader)
    except _DuplicateKey as exc:
        raise FileFormatError(path, f'{what} gives key {_shown(exc.key)} twice (first on line '
                              f'{exc.first_line}); remove one', exc.line) from None
    except yaml.YAMLError as exc:
        line = None
        mark = getattr(exc, 'problem_mark', None)
        if mark is not None:
            line = mark.line + 1
        reason = ' '.join(str(exc).split())
        raise FileFormatError(path, f'{what} is not valid YAML ({reason})', line) from None
    except (ValueError, TypeError, OverflowError, RecursionError) as exc:
        # e.g. an impossible date (2021-13-45) or nesting too deep for the parser
        raise FileFormatError(path, f'{what} is not valid YAML ({exc})') from None
    if not isinstance(data, dict):
        raise FileFormatError(path, f'{what} must be a YAML mapping, got '
                              f'{type(data).__name__} (empty or truncated file?)')
    if _expanded_size_exceeds(data, MAX_YAML_NODES):
        raise FileFormatError(path, f'{what} expands to more than {MAX_YAML_NODES} values '
                              '(nested aliases?); not a file this package writes')
    where = _too_large_integer(data)
    if where is not None:
        raise FileFormatError(path, f'"{where}" in the {what} holds a value too large for a '
                              f'number (beyond {sys.float_info.max:.4g})')
    return data


def _shown(value: Any) -> str:
    shown = repr(value)
    return shown if len(shown) <= 60 else shown[:57] + '...'


def _separator_count(text: str) -> int:
    """
    Count the characters that separate or open YAML nodes: ``, : - ? [ {`` and line breaks.

    A node needs at least one of them, and a flow mapping of bare keys (``{a, b}``) makes
    two nodes per comma: at most about twice this many values, a bound known before the
    parse (the count reads the text once per character, milliseconds for the size limit).
    """
    return sum(text.count(c) for c in ',:-?[{\n')


def _too_large_integer(data: Any) -> Optional[str]:
    """Return where (``scale[0]``, ``a.b``) an integer beyond a double sits, else None."""
    stack = [('', data)]
    seen = set()  # containers shared through aliases are looked at once
    while stack:
        where, item = stack.pop()
        if isinstance(item, (dict, list, tuple)):
            if id(item) in seen:
                continue
            seen.add(id(item))
        if isinstance(item, dict):
            stack.extend((f'{where}.{k}' if where else str(k), v) for k, v in item.items())
        elif isinstance(item, (list, tuple)):
            stack.extend((f'{where}[{k}]', v) for k, v in enumerate(item))
        elif isinstance(item, int) and not isinstance(item, bool) and abs(item) > _MAX_INT:
            return where
    return None


_MAX_INT = int(sys.float_info.max)


_YAML12_NUMBER = re.compile(r'^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$')


def yaml_number(value: Any) -> Optional[float]:
    """
    Return a YAML scalar as a float when it is a number, else None.

    An int or float is a number, a bool is not (``true`` is not 1.0). A string that YAML
    1.2 reads as a number (``1e-3``: PyYAML's YAML 1.1 reads it as text) counts too; an
    integer beyond a double is infinity (the caller's finiteness check names it).
    """
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        try:
            return float(value)
        except OverflowError:  # an int beyond a double (math.copysign would raise too)
            return math.inf if value > 0 else -math.inf
    if isinstance(value, str) and _YAML12_NUMBER.match(value.strip()):
        return float(value)
    return None


#: most values (after expanding YAML aliases) a file may hold: a guard against alias bombs
MAX_YAML_NODES = 1_000_000

#: most separators (:func:`_separator_count`) a YAML file may hold before it is parsed: at
#: most ~600000 values; the worst case at the limit (one dense flow list) parses in about
#: 2 s with libyaml. The package's own files hold hundreds to a few thousand (a calibration
#: ~8 per captured position); a rosbag2 ``metadata.yaml`` ~50 per topic with its QoS and
#: ~16 per split file: 1000 topics and 4000 split files are 1.4 MB and 107000 separators
#: (0.7 s), which the limit takes with room.
MAX_YAML_SEPARATORS = 300_000


def _expanded_size_exceeds(data, limit):
    """Whether ``data`` holds more than ``limit`` values counting shared ones each time."""
    count = 0
    stack = [data]
    while stack:
        item = stack.pop()
        count += 1
        if count > limit:
            return True
        if isinstance(item, dict):
            stack.extend(item.keys())
            stack.extend(item.values())
        elif isinstance(item, (list, tuple)):
            stack.extend(item)
    return False


def dump_yaml(data: Any) -> str:
    """YAML text with keys in insertion order and lists of numbers in flow style."""
    class _Dumper(yaml.SafeDumper):
        pass

    def _represent_list(dumper, value):
        flow = all(isinstance(v, (int, float)) for v in value)
        return dumper.represent_sequence('tag:yaml.org,2002:seq', value, flow_style=flow)

    _Dumper.add_representer(list, _represent_list)
    return yaml.dump(data, Dumper=_Dumper, sort_keys=False, default_flow_style=False)


def read_numeric_csv(path: PathLike, required: Sequence[str], optional: Sequence[str] = (),
                     finite: bool = False,
                     increasing: Optional[str] = None) -> Dict[str, 'np.ndarray']:
    """
    Read a CSV with a header into a dict of float arrays; errors name file and line.

    ``required`` columns must all be present; ``optional`` ones are returned if present;
    any other column, or a column named twice, is refused (the formats are
    :data:`accelcal_ros.schema.CSV_FORMATS`, listed in docs/formats.md). Every row must
    have as many fields as the header and only numbers; a short last row (truncated file)
    is reported with its line number. With ``finite=True`` a NaN or infinity is an error;
    ``increasing='t'`` requires column ``t`` to be finite and increase strictly.
    """
    import numpy as np

    path = os.fspath(path)
    text = read_input_text(path, 'CSV file', kind='csv')
    reader = csv.reader(io.StringIO(text, newline=''))
    try:
        rows = _numeric_rows(path, reader, required, optional, finite, increasing)
    except csv.Error as exc:
        raise FileFormatError(path, f'malformed CSV ({exc})', reader.line_num or 1) from None
    values, wanted = rows
    table = np.array(values, dtype=float).reshape(-1, len(wanted))
    return {name: table[:, k] for k, name in enumerate(wanted)}


def _numeric_rows(path, reader, required, optional, finite, increasing):
    try:
        header = next(reader)
    except StopIteration:
        raise FileFormatError(path, 'empty file (expected a header line)', 1) from None
    header = [h.strip() for h in header]
    expected = ','.join(list(required) + [f'[{c}]' for c in optional])
    missing = [c for c in required if c not in header]
    if missing:
        raise FileFormatError(path, f'header lacks column(s) {missing}; '
                              f'expected {expected}', 1)
    unknown = [c for c in header if c not in required and c not in optional]
    if unknown:
        raise FileFormatError(path, f'unknown column(s) {listed(unknown)}; this file holds '
                              f'only {expected} (misspelt, or another kind of file?)', 1)
    twice = sorted({c for c in header if header.count(c) > 1})
    if twice:
        raise FileFormatError(path, f'column(s) {listed(twice)} named more than once', 1)
    wanted = [c for c in list(required) + list(optional) if c in header]
    index = [header.index(c) for c in wanted]
    k_increasing = wanted.index(increasing) if increasing is not None else None
    rows = []
    for row in reader:
        line = reader.line_num
        if not row or all(not f.strip() for f in row):
            continue
        if len(row) != len(header):
            raise FileFormatError(path, f'expected {len(header)} fields, got {len(row)} '
                                  '(truncated or malformed line)', line)
        try:
            values = [float(row[i]) for i in index]
        except ValueError:
            shown = ','.join(row)
            shown = shown if len(shown) <= 80 else shown[:77] + '...'
            raise FileFormatError(path, f'non-numeric value in {shown!r}', line) from None
        if finite and not all(math.isfinite(v) for v in values):
            shown = ','.join(row)
            shown = shown if len(shown) <= 80 else shown[:77] + '...'
            raise FileFormatError(path, f'NaN or infinite value in {shown!r}', line)
        if k_increasing is not None:
            k = k_increasing
            if not math.isfinite(values[k]):
                raise FileFormatError(path, f'column {increasing} has a NaN or infinite value '
                                      f'({row[index[k]].strip()!r})', line)
            if rows and not values[k] > rows[-1][k]:
                raise FileFormatError(path, f'column {increasing} must increase strictly '
                                      f'({values[k]!r} after {rows[-1][k]!r})', line)
        rows.append(values)
    return rows, wanted
