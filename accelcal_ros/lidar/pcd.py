"""
PCD (Point Cloud Library) files: ``DATA ascii``, ``binary`` and ``binary_compressed``.

Read and written as PCL (``pcl::PCDReader``/``PCDWriter``) and LiDAR drivers write them:
header lines ``VERSION``, ``FIELDS``, ``SIZE``, ``TYPE``, ``COUNT``, ``WIDTH``, ``HEIGHT``,
``VIEWPOINT``, ``POINTS``, ``DATA``. Binary data is point-major (array of structs, packed);
``binary_compressed`` holds ``uint32 compressed_size, uint32 uncompressed_size`` and an
LZF stream (:mod:`.lzf`) of field-major data (all x, then all y, ...). A cloud is a numpy
structured array with one field per PCD field (``COUNT > 1`` -> a sub-array field); the
usual ones are ``x y z`` (m, LiDAR frame), ``intensity``, ``ring`` and a per-point time
(see :mod:`.cloud`). Errors name the file and the header line or byte offset; writes are
atomic (:func:`accelcal_ros.fileio.write_bytes_atomic`).
"""
import os
from typing import Any, Dict, Sequence, Tuple

from accelcal_ros.errors import FileFormatError, PathLike
from accelcal_ros.fileio import write_bytes_atomic
from accelcal_ros.lidar import lzf
from accelcal_ros.lidar.header import header_lines, read_file_bytes
import numpy as np

_TYPE_CODES = {('F', 4): 'f4', ('F', 8): 'f8', ('U', 1): 'u1', ('U', 2): 'u2', ('U', 4): 'u4',
               ('U', 8): 'u8', ('I', 1): 'i1', ('I', 2): 'i2', ('I', 4): 'i4', ('I', 8): 'i8'}
MAX_VALUES_PER_POINT = 10000
"""Most scalar values per point (the sum of COUNT): PCL's largest point types hold a few
hundred (ESF 640, SHOT 361, VFH 308); a header claiming more (COUNT 300000000 in a 90-byte
file) would allocate gigabytes before the data is looked at."""
_HEADER_KEYS = ('VERSION', 'FIELDS', 'SIZE', 'TYPE', 'COUNT', 'WIDTH', 'HEIGHT', 'VIEWPOINT',
                'POINTS', 'DATA')


def _dtype_from_header(path, header, lines):
    fields = header['FIELDS']
    if not fields:
        raise FileFormatError(path, 'FIELDS names no field', lines.get('FIELDS'))
    sizes = header.get('SIZE')
    types = header.get('TYPE')
    counts = header.get('COUNT', ['1'] * len(fields))
    for key, values in (('SIZE', sizes), ('TYPE', types), ('COUNT', counts)):
        if values is None:
            raise FileFormatError(path, f'header lacks the {key} line')
        if len(values) != len(fields):
            raise FileFormatError(path, f'{key} has {len(values)} entries for {len(fields)} '
                                  'FIELDS', lines.get(key))
    descr = []
    seen = {}
    total = 0
    for name, size, kind, count in zip(fields, sizes, types, counts):
        try:
            code = _TYPE_CODES[(kind.upper(), int(size))]
            count = int(count)
        except (KeyError, ValueError):
            raise FileFormatError(path, f'unsupported field {name!r}: TYPE {kind} SIZE {size} '
                                  f'COUNT {count}', lines.get('TYPE')) from None
        if count < 1:
            raise FileFormatError(path, f'field {name!r} has COUNT {count}', lines.get('COUNT'))
        total += count
        if total > MAX_VALUES_PER_POINT:
            raise FileFormatError(path, f'COUNT adds up to more than {MAX_VALUES_PER_POINT} '
                                  'values per point (a corrupt header?)', lines.get('COUNT'))
        if name == '_':  # PCL padding fields
            seen['_'] = seen.get('_', 0) + 1
            name = f'_pad{seen["_"]}'
        descr.append((name, '<' + code) if count == 1 else (name, '<' + code, (count,)))
    try:
        return np.dtype(descr)
    except (TypeError, ValueError) as exc:
        raise FileFormatError(path, f'bad FIELDS line ({exc})', lines.get('FIELDS')) from None


def _parse_header(path, raw):
    header, lines = {}, {}
    for line_no, text, offset in header_lines(
            path, raw, 'header ends before the DATA line (truncated file?)'):
        if not text or text.startswith('#'):
            continue
        parts = text.split()
        key = parts[0].upper()
        if key not in _HEADER_KEYS:
            raise FileFormatError(path, f'unknown header line {text!r}; is this a PCD file?',
                                  line_no)
        header[key] = parts[1:]
        lines[key] = line_no
        if key == 'DATA':
            return header, lines, offset, line_no


def read_pcd(path: PathLike) -> Tuple[np.ndarray, Dict[str, Any]]:
    """Return ``(cloud, meta)``: a structured array and ``{'viewpoint', 'data', 'width'}``."""
    path = os.fspath(path)
    raw = read_file_bytes(path)
    header, lines, offset, data_line = _parse_header(path, raw)
    if 'FIELDS' not in header:
        raise FileFormatError(path, 'header lacks the FIELDS line')
    dtype = _dtype_from_header(path, header, lines)
    try:
        width = int(header.get('WIDTH', ['0'])[0])
        height = int(header.get('HEIGHT', ['1'])[0])
        points = int(header['POINTS'][0]) if 'POINTS' in header else width * height
    except (ValueError, IndexError):
        raise FileFormatError(path, 'WIDTH, HEIGHT or POINTS is not an integer',
                              lines.get('POINTS', lines.get('WIDTH'))) from None
    if min(points, width, height) < 0 or (width * height != points and 'WIDTH' in header):
        raise FileFormatError(path, f'POINTS {points} != WIDTH {width} x HEIGHT {height}',
                              lines.get('POINTS'))
    kind = (header['DATA'] or [''])[0].lower()
    meta = {'data': kind, 'width': width, 'height': height,
            'viewpoint': _viewpoint(path, header, lines)}
    if kind == 'ascii':
        cloud = _read_ascii(path, raw[offset:], dtype, points, data_line)
    elif kind == 'binary':
        need = points * dtype.itemsize
        if len(raw) - offset < need:
            raise FileFormatError(path, f'binary data truncated: {len(raw) - offset} of {need} '
                                  f'bytes after byte offset {offset}')
        cloud = np.frombuffer(raw, dtype=dtype, count=points, offset=offset).copy()
    elif kind == 'binary_compressed':
        cloud = _read_compressed(path, raw, offset, dtype, points)
    else:
        raise FileFormatError(path, f'unsupported DATA {kind!r} (ascii, binary or '
                              'binary_compressed)', data_line)
    return cloud, meta


def _viewpoint(path, header, lines):
    """VIEWPOINT ``tx ty tz qw qx qy qz`` as 7 finite floats (default: identity)."""
    values = header.get('VIEWPOINT', ['0', '0', '0', '1', '0', '0', '0'])
    try:
        viewpoint = [float(v) for v in values]
    except ValueError:
        viewpoint = None
    if viewpoint is None or len(viewpoint) != 7 or not np.all(np.isfinite(viewpoint)):
        raise FileFormatError(path, f'VIEWPOINT must be 7 finite numbers (tx ty tz qw qx qy '
                              f'qz), got {" ".join(values)!r}', lines.get('VIEWPOINT'))
    return viewpoint


def _read_ascii(path, body, dtype, points, data_line):
    text = body.decode('ascii', errors='replace').splitlines()
    flat = []
    for name in dtype.names:
        sub = dtype[name]
        flat += [(name, k, sub.base if sub.shape else sub)
                 for k in range(int(np.prod(sub.shape)) if sub.shape else 1)]
    ncols = len(flat)
    rows = []
    line_no = data_line
    for line in text:
        line_no += 1
        parts = line.split()
        if not parts:
            continue
        if len(parts) != ncols:
            raise FileFormatError(path, f'expected {ncols} values, got {len(parts)} '
                                  '(truncated or malformed line)', line_no)
        rows.append((parts, line_no))
    if len(rows) < points:
        raise FileFormatError(path, f'only {len(rows)} of {points} points (truncated file)',
                              line_no)
    if len(rows) > points:
        raise FileFormatError(path, f'{len(rows)} data lines but POINTS is {points}',
                              rows[points][1])
    cloud = np.zeros(points, dtype=dtype)
    if points == 0:
        return cloud
    try:
        table = np.array([r[0] for r in rows], dtype=float)
    except ValueError:
        for parts, number in rows:
            try:
                [float(p) for p in parts]
            except ValueError:
                raise FileFormatError(path, f'non-numeric value in {" ".join(parts)!r}',
                                      number) from None
        raise
    col = 0
    for name in dtype.names:
        sub = dtype[name]
        width = int(np.prod(sub.shape)) if sub.shape else 1
        values = table[:, col:col + width]
        cloud[name] = values[:, 0] if not sub.shape else values
        col += width
    return cloud


def _read_compressed(path, raw, offset, dtype, points):
    if len(raw) - offset < 8:
        raise FileFormatError(path, f'binary_compressed data truncated at byte offset {offset} '
                              '(no size words)')
    sizes = np.frombuffer(raw, dtype='<u4', count=2, offset=offset)
    compressed, uncompressed = int(sizes[0]), int(sizes[1])
    start = offset + 8
    if len(raw) - start < compressed:
        raise FileFormatError(path, f'binary_compressed data truncated: {len(raw) - start} of '
                              f'{compressed} compressed bytes after byte offset {start}')
    if uncompressed != points * dtype.itemsize:
        raise FileFormatError(path, f'uncompressed size {uncompressed} != {points} points x '
                              f'{dtype.itemsize} bytes (byte offset {offset})')
    if uncompressed > lzf.MAX_RATIO * compressed + lzf.MAX_LITERAL:
        raise FileFormatError(path, f'{compressed} LZF bytes cannot hold {uncompressed} bytes '
                              f'(byte offset {offset}): corrupt sizes')
    try:
        data = lzf.decompress(raw[start:start + compressed], uncompressed)
    except lzf.LzfError as exc:
        raise FileFormatError(path, f'corrupt LZF data: {exc} (data starts at byte offset '
                              f'{start})') from None
    cloud = np.zeros(points, dtype=dtype)
    pos = 0
    for name in dtype.names:
        sub = dtype[name]
        nbytes = points * sub.itemsize
        count = points * (int(np.prod(sub.shape)) if sub.shape else 1)
        block = np.frombuffer(data, dtype=sub.base, count=count, offset=pos)
        cloud[name] = block.reshape((points,) + sub.shape)
        pos += nbytes
    return cloud


def _header_text(cloud, data, viewpoint, width=None, height=None):
    fields, sizes, types, counts = [], [], [], []
    for name in cloud.dtype.names:
        sub = cloud.dtype[name]
        base = sub.base
        kind = {'f': 'F', 'u': 'U', 'i': 'I'}.get(base.kind)
        if kind is None or (kind, base.itemsize) not in _TYPE_CODES:
            raise ValueError(f'field {name!r} of dtype {base} cannot be written to PCD')
        fields.append('_' if name.startswith('_pad') else name)
        sizes.append(str(base.itemsize))
        types.append(kind)
        counts.append(str(int(np.prod(sub.shape)) if sub.shape else 1))
    n = cloud.shape[0]
    width = n if width is None else width
    height = 1 if height is None else height
    vp = ' '.join(f'{v:g}' for v in viewpoint)
    return ('# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n'
            f'FIELDS {" ".join(fields)}\nSIZE {" ".join(sizes)}\nTYPE {" ".join(types)}\n'
            f'COUNT {" ".join(counts)}\nWIDTH {width}\nHEIGHT {height}\nVIEWPOINT {vp}\n'
            f'POINTS {n}\nDATA {data}\n')


def pcd_bytes(cloud: np.ndarray, data: str = 'binary',
              viewpoint: Sequence[float] = (0, 0, 0, 1, 0, 0, 0)) -> bytes:
    """Return the PCD file contents of structured array ``cloud`` (``data`` as PCD DATA)."""
    cloud = np.ascontiguousarray(cloud)
    names = cloud.dtype.names
    if names is None:
        raise ValueError(f'a PCD file holds a structured array (named fields), not {cloud.dtype}')
    le = cloud.astype(cloud.dtype.newbyteorder('<'))
    header = _header_text(cloud, data, viewpoint).encode('ascii')
    if data == 'binary':
        return header + _packed(le).tobytes()
    if data == 'binary_compressed':
        packed = _packed(le)
        blocks = [np.ascontiguousarray(packed[name]).tobytes() for name in packed.dtype.names]
        raw = b''.join(blocks)
        comp = lzf.compress(raw)
        return header + np.array([len(comp), len(raw)], dtype='<u4').tobytes() + comp
    if data == 'ascii':
        columns, formats = [], []
        for name in names:
            values = np.asarray(cloud[name]).reshape(len(cloud), -1)
            fmt = '%.9g' if values.dtype.kind == 'f' and values.dtype.itemsize == 4 else (
                '%.17g' if values.dtype.kind == 'f' else '%d')
            for k in range(values.shape[1]):
                columns.append(values[:, k].tolist())
                formats.append(fmt)
        row_format = ' '.join(formats)
        lines = [row_format % row for row in zip(*columns)]
        return header + ('\n'.join(lines) + ('\n' if lines else '')).encode('ascii')
    raise ValueError(f'unknown PCD data kind {data!r} (ascii, binary, binary_compressed)')


def _packed(cloud):
    names = cloud.dtype.names
    packed = np.zeros(cloud.shape[0], dtype=[(n, cloud.dtype[n]) for n in names])
    for n in names:
        packed[n] = cloud[n]
    return packed


def write_pcd(path: PathLike, cloud: np.ndarray, data: str = 'binary',
              viewpoint: Sequence[float] = (0, 0, 0, 1, 0, 0, 0)) -> None:
    """Write structured array ``cloud`` to ``path`` atomically (``data``: PCD DATA kind)."""
    write_bytes_atomic(path, pcd_bytes(cloud, data, viewpoint))
