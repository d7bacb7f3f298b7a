"""
File helpers: atomic writes (with optional backup) and YAML/CSV reading with clear errors.

A file is never left half-written: data goes to a temporary file in the same directory,
is flushed and fsync'ed, then ``os.replace`` puts it in place (atomic on POSIX). With
``backup=True`` the previous file is kept as ``<name>.bak``.
"""
import csv
import io
import math
import os
import tempfile

from accelcal_ros.errors import FileFormatError
import yaml


def write_bytes_atomic(path, data, backup=False):
    """Write ``data`` (bytes) to ``path`` atomically; keep the old file as ``path.bak``."""
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix='.' + os.path.basename(path) + '.', dir=directory)
    try:
        with os.fdopen(fd, 'wb') as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        if backup and os.path.exists(path):
            bak = path + '.bak'
            tmp_bak = bak + '.tmp'
            with open(path, 'rb') as src, open(tmp_bak, 'wb') as dst:
                dst.write(src.read())
            os.replace(tmp_bak, bak)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_text_atomic(path, text, backup=False):
    """Write ``text`` (UTF-8) to ``path`` atomically (see :func:`write_bytes_atomic`)."""
    write_bytes_atomic(path, text.encode('utf-8'), backup=backup)


def write_with_atomic(path, writer, backup=False, binary=False):
    """
    Call ``writer(handle)`` on an in-memory buffer, then write it atomically.

    For writers that need a file object (numpy, csv, OpenCV encoders): nothing reaches
    ``path`` unless ``writer`` returns without raising.
    """
    buffer = io.BytesIO() if binary else io.StringIO()
    writer(buffer)
    data = buffer.getvalue()
    write_bytes_atomic(path, data if binary else data.encode('utf-8'), backup=backup)


def load_yaml_mapping(path, what='file'):
    """Load a YAML file whose top level must be a mapping; raise FileFormatError otherwise."""
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileFormatError(path, f'{what} not found')
    try:
        with open(path, 'r', encoding='utf-8') as handle:
            data = yaml.safe_load(handle)
    except yaml.YAMLError as exc:
        line = None
        mark = getattr(exc, 'problem_mark', None)
        if mark is not None:
            line = mark.line + 1
        raise FileFormatError(path, f'{what} is not valid YAML ({exc})', line) from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise FileFormatError(path, f'cannot read {what}: {exc}') from exc
    if not isinstance(data, dict):
        raise FileFormatError(path, f'{what} must be a YAML mapping, got '
                              f'{type(data).__name__} (empty or truncated file?)')
    return data


def dump_yaml(data):
    """YAML text with keys in insertion order and lists of numbers in flow style."""
    class _Dumper(yaml.SafeDumper):
        pass

    def _represent_list(dumper, value):
        flow = all(isinstance(v, (int, float)) for v in value)
        return dumper.represent_sequence('tag:yaml.org,2002:seq', value, flow_style=flow)

    _Dumper.add_representer(list, _represent_list)
    return yaml.dump(data, Dumper=_Dumper, sort_keys=False, default_flow_style=False)


def read_numeric_csv(path, required, optional=(), finite=False, increasing=None):
    """
    Read a CSV with a header into a dict of float arrays; errors name file and line.

    ``required`` columns must all be present; ``optional`` ones are returned if present.
    Every row must have as many fields as the header and only numbers; a short last row
    (truncated file) is reported with its line number. With ``finite=True`` a NaN or
    infinity is an error; ``increasing='t'`` requires column ``t`` to increase strictly.
    """
    import numpy as np

    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileFormatError(path, 'file not found')
    with open(path, 'r', encoding='utf-8', newline='') as handle:
        reader = csv.reader(handle)
        try:
            header = next(reader)
        except StopIteration:
            raise FileFormatError(path, 'empty file (expected a header line)', 1) from None
        header = [h.strip() for h in header]
        missing = [c for c in required if c not in header]
        if missing:
            raise FileFormatError(path, f'header lacks column(s) {missing}; '
                                  f'expected {",".join(list(required) + list(optional))}', 1)
        wanted = [c for c in list(required) + list(optional) if c in header]
        index = [header.index(c) for c in wanted]
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
                raise FileFormatError(path, f'non-numeric value in {row!r}', line) from None
            if finite and not all(math.isfinite(v) for v in values):
                raise FileFormatError(path, f'NaN or infinite value in {row!r}', line)
            if increasing is not None and rows:
                k = wanted.index(increasing)
                if not values[k] > rows[-1][k]:
                    raise FileFormatError(path, f'column {increasing} must increase strictly '
                                          f'({values[k]!r} after {rows[-1][k]!r})', line)
            rows.append(values)
    data = np.array(rows, dtype=float).reshape(-1, len(wanted))
    return {name: data[:, k] for k, name in enumerate(wanted)}
