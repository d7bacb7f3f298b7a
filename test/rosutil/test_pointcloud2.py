"""PointCloud2 <-> numpy structured arrays (the sensor_msgs_py equivalent)."""
from accelcal_ros.errors import InputError
from accelcal_ros.rosutil.pointcloud2 import array_to_pointcloud2, pointcloud2_to_array
import numpy as np
import pytest
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header


def _cloud(n=100):
    rng = np.random.default_rng(0)
    cloud = np.zeros(n, dtype=[('x', 'f4'), ('y', 'f4'), ('z', 'f4'), ('intensity', 'f4'),
                               ('ring', 'u2'), ('time', 'f4'), ('stamp', 'f8')])
    for name in cloud.dtype.names:
        cloud[name] = rng.uniform(0, 100, n)
    return cloud


def test_round_trip_keeps_fields_and_header():
    """Every field, its datatype and the header survive a round trip."""
    cloud = _cloud()
    header = Header(frame_id='velodyne')
    msg = array_to_pointcloud2(cloud, PointCloud2, PointField, header)
    assert msg.header.frame_id == 'velodyne' and msg.width == 100 and msg.height == 1
    assert [f.datatype for f in msg.fields] == [7, 7, 7, 7, 4, 7, 8]
    assert msg.point_step == 30 and msg.is_dense
    back = pointcloud2_to_array(msg)
    for name in cloud.dtype.names:
        np.testing.assert_array_equal(back[name], cloud[name])


def test_padded_organised_big_endian_cloud():
    """Driver-style padding (point_step 32), 2 rows with row padding, big-endian data."""
    rows, width = 2, 3
    dtype = np.dtype({'names': ['x', 'y', 'z', 'intensity', 'ring', 'time'],
                      'formats': ['>f4', '>f4', '>f4', '>f4', '>u2', '>f4'],
                      'offsets': [0, 4, 8, 16, 20, 24], 'itemsize': 32})
    values = np.zeros(rows * width, dtype=dtype)
    values['x'] = np.arange(6)
    values['ring'] = np.arange(6) + 10
    values['time'] = np.linspace(0, 1, 6)
    raw = values.tobytes()
    row_step = width * 32 + 8
    data = b''.join(raw[r * width * 32:(r + 1) * width * 32] + b'\0' * 8 for r in range(rows))
    fields = []
    for name, off, dt in (('x', 0, 7), ('y', 4, 7), ('z', 8, 7), ('intensity', 16, 7),
                          ('ring', 20, 4), ('time', 24, 7)):
        fields.append(PointField(name=name, offset=off, datatype=dt, count=1))
    msg = PointCloud2(height=rows, width=width, fields=fields, is_bigendian=True,
                      point_step=32, row_step=row_step, data=data, is_dense=True)
    back = pointcloud2_to_array(msg)
    assert back['x'].tolist() == list(range(6)) and back['ring'].tolist() == list(range(10, 16))
    np.testing.assert_allclose(back['time'], np.linspace(0, 1, 6), rtol=1e-6)
    assert back.dtype['x'].byteorder in ('=', '<')


def test_bad_messages_raise_clear_errors():
    """Short or over-long data and unknown datatypes raise InputError; empty clouds are fine."""
    msg = array_to_pointcloud2(_cloud(10), PointCloud2, PointField)
    msg.data = msg.data[:-5]
    with pytest.raises(InputError, match='too short'):
        pointcloud2_to_array(msg)
    msg = array_to_pointcloud2(_cloud(10), PointCloud2, PointField)
    msg.data = bytes(msg.data) + bytes(77)   # more than the header describes
    with pytest.raises(InputError, match='too long'):
        pointcloud2_to_array(msg)
    msg = array_to_pointcloud2(_cloud(2), PointCloud2, PointField)
    msg.fields[0].datatype = 42
    with pytest.raises(InputError, match='unknown datatype'):
        pointcloud2_to_array(msg)
    msg = array_to_pointcloud2(_cloud(2), PointCloud2, PointField)
    msg.fields[0].datatype = 8   # x as FLOAT64 over y: was read, x -8.6e7..4.3e9 m
    with pytest.raises(InputError, match="'x' and 'y' overlap"):
        pointcloud2_to_array(msg)
    empty = array_to_pointcloud2(_cloud(0), PointCloud2, PointField)
    assert len(pointcloud2_to_array(empty)) == 0
    nan = _cloud(3)
    nan['x'][1] = np.nan
    assert not array_to_pointcloud2(nan, PointCloud2, PointField).is_dense
