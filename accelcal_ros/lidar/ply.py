"""
PLY (Stanford polygon) point clouds: ``format ascii 1.0`` and ``binary_little_endian 1.0``.

Only the ``vertex`` element is read (it must come first, as every point-cloud writer
puts it); its scalar properties become the fields of a numpy structured array (``x y z``
in m plus e.g. ``intensity``, ``ring``, ``time``). Other elements after it are ignored.
Errors name the file and the header line or byte offset; writes are atomic.
"""
import os
from typing import Dict, List, Set, Tuple

from accelcal_ros.errors import FileFormatError, PathLike
from accelcal_ros.fileio import write_bytes_atomic
from accelcal_ros.lidar.header import header_lines, read_file_bytes
import numpy as np

_PLY_TYPES = {'char': 'i1', 'int8': 'i1', 'uchar': 'u1', 'uint8': 'u1', 'short': 'i2',
              'int16': 'i2', 'ushort': 'u2', 'uint16': 'u2', 'int': 'i4', 'int32': 'i4',
              'uint': 'u4', 'uint32': 'u4', 'float': 'f4', 'float32': 'f4', 'double': 'f8',
              'float64': 'f8'}
MAX_PROPERTIES = 10000
"""Most properties of one element (point clouds have a handful; 50000 took 31 s to read)."""
_WRITE_NAMES = {'i1': 'char', 'u1': 'uchar', 'i2': 'short', 'u2': 'ushort', 'i4': 'int',
                'u4': 'uint', 'f4': 'float', 'f8': 'double'}


def read_ply(path: PathLike) -> np.ndarray:
    """Return the ``vertex`` element of a PLY file as a structured array."""
    path = os.fspath(path)
    raw = read_file_bytes(path)
    if not raw.startswith(b'ply'):
        raise FileFormatError(path, 'not a PLY file (first line is not "ply")', 1)
    fmt = None
    elements: List[Tuple[str, int, List[Tuple[str, str]]]] = []
    names: Dict[int, Set[str]] = {}   # per element (1-based): its property names
    for line_no, text, offset in header_lines(
            path, raw, 'header has no end_header line (truncated file?)'):
        parts = text.split()
        if not parts or parts[0] in ('ply', 'comment', 'obj_info'):
            continue
        if parts[0] == 'format':
            if len(parts) < 2 or parts[1] not in ('ascii', 'binary_little_endian'):
                raise FileFormatError(path, f'unsupported PLY format {text!r} (ascii or '
                                      'binary_little_endian)', line_no)
            fmt = parts[1]
        elif parts[0] == 'element' and len(parts) == 3:
            try:
                count = int(parts[2])
            except ValueError:
                count = -1
            if count < 0:
                raise FileFormatError(path, f'bad element count in {text!r}', line_no)
            elements.append((parts[1], count, []))
            names[len(elements)] = set()
        elif parts[0] == 'property' and elements:
            if len(elements[-1][2]) >= MAX_PROPERTIES:
                raise FileFormatError(path, f'element {elements[-1][0]!r} has more than '
                                      f'{MAX_PROPERTIES} properties (a corrupt header?)',
                                      line_no)
            _add_property(path, elements[-1][2], parts, text, line_no, names[len(elements)])
        elif parts[0] == 'end_header':
            break
        else:
            raise FileFormatError(path, f'unexpected header line {text!r}', line_no)
    if fmt is None:
        raise FileFormatError(path, 'header lacks the format line')
    if not elements or elements[0][0] != 'vertex':
        raise FileFormatError(path, 'the first element must be "vertex"')
    _, count, props = elements[0]
    if any(p[0] == 'list' for p in props):
        raise FileFormatError(path, 'list properties in the vertex element are not supported')
    if not props:
        raise FileFormatError(path, 'the vertex element has no property')
    dtype = np.dtype([(name, '<' + code) for name, code in props])
    if fmt == 'binary_little_endian':
        need = count * dtype.itemsize
        if len(raw) - offset < need:
            raise FileFormatError(path, f'vertex data truncated: {len(raw) - offset} of {need} '
                                  f'bytes after byte offset {offset}')
        return np.frombuffer(raw, dtype=dtype, count=count, offset=offset).copy()
    lines = raw[offset:].decode('ascii', errors='replace').splitlines()
    rows: List[List[float]] = []
    number = line_no
    for line in lines:
        if len(rows) == count:
            break
        number += 1
        parts = line.split()
        if not parts:
            continue
        if len(parts) != len(props):
            raise FileFormatError(path, f'expected {len(props)} values, got {len(parts)} '
                                  '(truncated or malformed line)', number)
        try:
            rows.append([float(p) for p in parts])
        except ValueError:
            raise FileFormatError(path, f'non-numeric value in {line.strip()!r}', number) from None
    if len(rows) < count:
        raise FileFormatError(path, f'only {len(rows)} of {count} vertices (truncated file)',
                              number)
    table = np.array(rows, dtype=float).reshape(count, len(props))
    cloud = np.zeros(count, dtype=dtype)
    for k, (name, _) in enumerate(props):
        cloud[name] = table[:, k]
    return cloud


def _add_property(path, props, parts, text, line_no, names):
    """
    Append ``(name, code)`` of a ``property TYPE NAME`` line (``list`` ones as 'list').

    ``names``: the element's property names so far (updated).
    """
    if len(parts) >= 2 and parts[1] == 'list':
        if len(parts) != 5:
            raise FileFormatError(path, f'malformed list property {text!r} (property list '
                                  'COUNT_TYPE ITEM_TYPE NAME)', line_no)
        props.append(('list', parts[-1]))
        return
    if len(parts) != 3 or parts[1] not in _PLY_TYPES:
        raise FileFormatError(path, f'unsupported property {text!r} (property TYPE NAME, '
                              f'TYPE one of {", ".join(sorted(_PLY_TYPES))})', line_no)
    if parts[2] in names:
        raise FileFormatError(path, f'property {parts[2]!r} defined twice', line_no)
    names.add(parts[2])
    props.append((parts[2], _PLY_TYPES[parts[1]]))


def ply_bytes(cloud: np.ndarray, binary: bool = True) -> bytes:
    """Return PLY file contents (vertex element only) for a structured array."""
    names = cloud.dtype.names
    if names is None:
        raise ValueError(f'a PLY file holds a structured array (named fields), not {cloud.dtype}')
    props = []
    for name in names:
        base = cloud.dtype[name]
        code = base.str[1:]
        if base.shape or code not in _WRITE_NAMES:
            raise ValueError(f'field {name!r} of dtype {base} cannot be written to PLY')
        props.append(f'property {_WRITE_NAMES[code]} {name}')
    fmt = 'binary_little_endian' if binary else 'ascii'
    header = (f'ply\nformat {fmt} 1.0\ncomment written by accelcal_ros\n'
              f'element vertex {len(cloud)}\n' + '\n'.join(props) + '\nend_header\n')
    if binary:
        le = np.dtype([(n, cloud.dtype[n].newbyteorder('<')) for n in names])
        packed = np.zeros(len(cloud), dtype=le)
        for n in names:
            packed[n] = cloud[n]
        return header.encode('ascii') + packed.tobytes()
    columns, formats = [], []
    for name in names:
        values = cloud[name]
        formats.append('%.17g' if values.dtype.itemsize == 8 and values.dtype.kind == 'f'
                       else ('%.9g' if values.dtype.kind == 'f' else '%d'))
        columns.append(values.tolist())
    row_format = ' '.join(formats)
    body = '\n'.join(row_format % row for row in zip(*columns))
    return (header + body + ('\n' if len(cloud) else '')).encode('ascii')


def write_ply(path: PathLike, cloud: np.ndarray, binary: bool = True) -> None:
    """Write structured array ``cloud`` to ``path`` atomically as PLY."""
    write_bytes_atomic(path, ply_bytes(cloud, binary))
