"""
sensor_msgs/PointCloud2 <-> numpy structured arrays: the part of sensor_msgs_py we need.

:func:`pointcloud2_to_array` honours every field's ``offset``, ``datatype`` and ``count``,
``point_step`` padding, ``row_step`` and ``is_bigendian`` (fields that overlap are refused:
an ``x`` made FLOAT64 over ``y`` read as -8.6e7..4.3e9 m, status 0); it returns a packed structured
array (one row per point, ``height * width`` points, rows concatenated). Fields this
package does not know (e.g. ``rgb`` packed as float32) are kept as they are.
:func:`array_to_pointcloud2` builds the message from a structured array (``is_dense`` is
set from the finiteness of ``x y z``). Pure numpy; the message classes are passed in.
"""
from accelcal_ros.errors import InputError
import numpy as np

# sensor_msgs/PointField datatypes
_DATATYPES = {1: 'i1', 2: 'u1', 3: 'i2', 4: 'u2', 5: 'i4', 6: 'u4', 7: 'f4', 8: 'f8'}
_CODES = {v: k for k, v in _DATATYPES.items()}


def dtype_from_fields(fields, point_step, is_bigendian=False):
    """Return the numpy dtype (with offsets and itemsize ``point_step``) of PointFields."""
    order = '>' if is_bigendian else '<'
    names, formats, offsets = [], [], []
    for f in fields:
        if f.datatype not in _DATATYPES:
            raise InputError(f'PointCloud2 field {f.name!r} has unknown datatype {f.datatype}')
        base = np.dtype(order + _DATATYPES[f.datatype])
        names.append(f.name)
        formats.append(base if f.count <= 1 else np.dtype((base, (f.count,))))
        offsets.append(f.offset)
    spans = sorted((offset, offset + fmt.itemsize, name)
                   for name, fmt, offset in zip(names, formats, offsets))
    for (_, end, name), (start, _, other) in zip(spans, spans[1:]):
        if start < end:
            raise InputError(f'PointCloud2 fields {name!r} and {other!r} overlap (bytes '
                             f'{start}-{end - 1}): the header does not describe the data')
    try:
        return np.dtype({'names': names, 'formats': formats, 'offsets': offsets,
                         'itemsize': point_step})
    except ValueError as exc:
        raise InputError(f'PointCloud2 fields do not fit point_step {point_step}: {exc}') \
            from None


def pointcloud2_to_array(msg):
    """Return the points of a PointCloud2 as a packed, native-endian structured array."""
    n_rows, width = int(msg.height), int(msg.width)
    if n_rows * width == 0:
        dtype = dtype_from_fields(msg.fields, max(int(msg.point_step), 1), msg.is_bigendian)
        return np.zeros(0, dtype=_packed_dtype(dtype))
    dtype = dtype_from_fields(msg.fields, int(msg.point_step), msg.is_bigendian)
    row_step = int(msg.row_step) or width * int(msg.point_step)
    step = int(msg.point_step)
    buf = msg.data if isinstance(msg.data, (bytes, bytearray)) else memoryview(msg.data)
    need = row_step * (n_rows - 1) + width * step
    if len(buf) < need:
        raise InputError(f'PointCloud2 data too short: {len(buf)} bytes for {width} x '
                         f'{n_rows} points of {step} bytes (row_step {row_step})')
    if len(buf) > row_step * n_rows:   # the header does not describe the data
        raise InputError(f'PointCloud2 data too long: {len(buf)} bytes for {width} x '
                         f'{n_rows} points of {step} bytes (row_step {row_step}: at most '
                         f'{row_step * n_rows})')
    if row_step == width * step:
        rows = np.frombuffer(buf, dtype=dtype, count=n_rows * width)
    else:
        raw = np.frombuffer(buf, dtype=np.uint8, count=need)
        parts = [raw[r * row_step:r * row_step + width * step] for r in range(n_rows)]
        rows = np.frombuffer(np.concatenate(parts).tobytes(), dtype=dtype)
    packed = np.zeros(len(rows), dtype=_packed_dtype(dtype))
    for name in dtype.names:
        packed[name] = rows[name]
    return packed


def _packed_dtype(dtype):
    return np.dtype([(n, dtype[n].newbyteorder('=') if not dtype[n].shape else
                      (dtype[n].base.newbyteorder('='), dtype[n].shape)) for n in dtype.names])


def array_to_pointcloud2(cloud, pointcloud2_type, pointfield_type, header=None):
    """Build a ``pointcloud2_type()`` holding structured array ``cloud`` (unorganised)."""
    cloud = np.ascontiguousarray(cloud)
    if cloud.dtype.names is None:
        raise InputError('array_to_pointcloud2 needs a structured array with named fields')
    packed_dtype = np.dtype([(n, cloud.dtype[n].base.newbyteorder('<'), cloud.dtype[n].shape)
                             if cloud.dtype[n].shape else
                             (n, cloud.dtype[n].newbyteorder('<'))
                             for n in cloud.dtype.names])
    packed = np.zeros(len(cloud), dtype=packed_dtype)
    fields = []
    for name in cloud.dtype.names:
        packed[name] = cloud[name]
        sub = packed_dtype[name]
        code = _CODES.get(sub.base.str[1:])
        if code is None:
            raise InputError(f'field {name!r} of dtype {sub.base} has no PointField datatype')
        field = pointfield_type()
        field.name = name
        field.offset = packed_dtype.fields[name][1]
        field.datatype = code
        field.count = int(np.prod(sub.shape)) if sub.shape else 1
        fields.append(field)
    msg = pointcloud2_type()
    if header is not None:
        msg.header = header
    msg.height = 1
    msg.width = len(cloud)
    msg.fields = fields
    msg.is_bigendian = False
    msg.point_step = packed_dtype.itemsize
    msg.row_step = packed_dtype.itemsize * len(cloud)
    names = cloud.dtype.names
    if all(n in names for n in ('x', 'y', 'z')) and len(cloud):
        msg.is_dense = bool(np.all(np.isfinite(cloud['x']) & np.isfinite(cloud['y'])
                                   & np.isfinite(cloud['z'])))
    else:
        msg.is_dense = True
    msg.data = packed.tobytes()
    return msg
