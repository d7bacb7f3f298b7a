"""PCD (ascii, binary, binary_compressed with LZF), PLY, IMU and pose CSV files."""
import os
import warnings

from accelcal_ros.errors import FileFormatError, InputError
from accelcal_ros.lidar import lzf
from accelcal_ros.lidar.cloud import make_cloud, point_times, read_cloud, write_cloud, xyz
from accelcal_ros.lidar.imu_log import read_imu_csv
from accelcal_ros.lidar.pcd import pcd_bytes, read_pcd, write_pcd
from accelcal_ros.lidar.ply import read_ply, write_ply
from accelcal_ros.lidar.poses import PoseStream, read_poses_csv, write_poses_csv
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest


def _cloud(n=500, seed=0):
    rng = np.random.default_rng(seed)
    return make_cloud(rng.normal(size=(n, 3)) * 5, rng.uniform(0, 255, n),
                      np.arange(n) % 16, np.linspace(0, 0.1, n))


_BACKENDS = [(lzf.compress_python, lzf.decompress_python, 'python')]
if lzf.c_available():
    _BACKENDS.append((lzf.compress_c, lzf.decompress_c, 'c'))
_IDS = [b[2] for b in _BACKENDS]


@pytest.mark.parametrize('backend', _BACKENDS, ids=_IDS)
def test_lzf_hand_made_stream(backend):
    """A literal then an overlapping back reference, as liblzf encodes runs."""
    _, decompress, _ = backend
    assert decompress(b'\x00a\xe0\x00\x00', 10) == b'a' * 10
    # literal "abc", then a reference of length 3 at offset 3 -> "abcabc"
    assert decompress(b'\x02abc\x20\x02', 6) == b'abcabc'


@settings(max_examples=60, deadline=None)
@given(st.binary(max_size=3000), st.integers(1, 5))
def test_lzf_round_trip_and_cross_decompression(data, repeat):
    """Each backend's stream decompresses to the input with every backend (C <-> Python)."""
    for blob in (data, data * repeat):
        for compress, _, _ in _BACKENDS:
            packed = compress(blob)
            for _, decompress, _ in _BACKENDS:
                assert decompress(packed, len(blob)) == blob


def test_lzf_cross_decompression_of_a_scan():
    """A real binary_compressed payload (field-major floats) crosses between the backends."""
    blob = _cloud(3000).tobytes()
    for compress, _, _ in _BACKENDS:
        packed = compress(blob)
        assert len(packed) < len(blob)
        for _, decompress, _ in _BACKENDS:
            assert decompress(packed, len(blob)) == blob
    assert lzf.BACKEND in ('c', 'python')


@pytest.mark.parametrize('backend', _BACKENDS, ids=_IDS)
def test_lzf_compresses_repetition_and_rejects_corruption(backend):
    """Repetitive data shrinks; corrupt, short or oversized streams raise LzfError."""
    compress, decompress, name = backend
    blob = np.repeat(np.arange(50, dtype=np.uint16), 400).tobytes()
    packed = compress(blob)
    assert len(packed) < len(blob) / 20
    with pytest.raises(lzf.LzfError, match='compressed byte' if name == 'python' else None):
        decompress(packed[:-3], len(blob))
    with pytest.raises(lzf.LzfError):
        decompress(b'\x20\x05', 3)  # reference before the start
    with pytest.raises(lzf.LzfError):
        decompress(packed, len(blob) - 1)  # decodes to more than expected
    with pytest.raises(lzf.LzfError):
        decompress(packed, len(blob) + 1)  # decodes to less than expected


@pytest.mark.parametrize('data', ['ascii', 'binary', 'binary_compressed'])
def test_pcd_round_trip(tmp_path, data):
    """Every PCD encoding gives the same fields and values back."""
    cloud = _cloud()
    path = tmp_path / f'c_{data}.pcd'
    write_pcd(path, cloud, data)
    back, meta = read_pcd(path)
    assert meta['data'] == data and back.dtype.names == cloud.dtype.names
    for name in cloud.dtype.names:
        np.testing.assert_array_equal(back[name], cloud[name])


def test_pcd_as_pcl_writes_it(tmp_path):
    """A PCL-style ascii file with a padding field, COUNT 1 and comments is read."""
    text = ('# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n'
            'FIELDS x y z intensity _ ring time\nSIZE 4 4 4 4 1 2 4\nTYPE F F F F U U F\n'
            'COUNT 1 1 1 1 1 1 1\nWIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\n'
            'DATA ascii\n1 2 3 10 0 5 0.001\n-1.5 0.25 nan 20 0 7 0.002\n')
    path = tmp_path / 'pcl.pcd'
    path.write_text(text)
    cloud, _ = read_pcd(path)
    assert cloud['ring'].tolist() == [5, 7]
    assert np.isnan(cloud['z'][1]) and cloud['x'][1] == -1.5
    np.testing.assert_allclose(point_times(cloud, 100.0), [100.001, 100.002])


def test_pcd_errors_name_file_and_place(tmp_path):
    """Truncated and malformed PCD files: errors name the file and line or offset."""
    cloud = _cloud(100)
    raw = pcd_bytes(cloud, 'binary')
    bad = tmp_path / 'trunc.pcd'
    bad.write_bytes(raw[:-10])
    with pytest.raises(FileFormatError, match=r'trunc\.pcd: binary data truncated.*offset'):
        read_pcd(bad)
    comp = tmp_path / 'comp.pcd'
    comp.write_bytes(pcd_bytes(cloud, 'binary_compressed')[:-50])
    with pytest.raises(FileFormatError, match='comp.pcd'):
        read_pcd(comp)
    text = pcd_bytes(cloud[:3], 'ascii').decode().splitlines()
    text[-1] = '1 2'
    asc = tmp_path / 'short.pcd'
    asc.write_text('\n'.join(text) + '\n')
    with pytest.raises(FileFormatError, match=r'short\.pcd:14: expected 6 values'):
        read_pcd(asc)
    hdr = tmp_path / 'hdr.pcd'
    hdr.write_text('VERSION 0.7\nFIELDS x y z\nSIZE 4 4\n')
    with pytest.raises(FileFormatError, match='hdr.pcd'):
        read_pcd(hdr)


@pytest.mark.parametrize('change, words', [
    (('VIEWPOINT 0 0 0 1 0 0 0', 'VIEWPOINT 0 0 abc 1 0 0 0'), r':9: VIEWPOINT must be 7'),
    (('VIEWPOINT 0 0 0 1 0 0 0', 'VIEWPOINT 0 0 0'), r':9: VIEWPOINT must be 7'),
    (('VIEWPOINT 0 0 0 1 0 0 0', 'VIEWPOINT 0 0 nan 1 0 0 0'), r':9: VIEWPOINT must be 7'),
    (('FIELDS x y z intensity ring time', 'FIELDS'), r'FIELDS names no field'),
    (('FIELDS x y z intensity ring time', 'FIELDS x x z intensity ring time'), 'FIELDS'),
    (('WIDTH 40', 'WIDTH -40'), 'POINTS'),
])
def test_pcd_header_values_are_checked(tmp_path, change, words):
    """Non-numeric VIEWPOINT, empty or duplicated FIELDS, negative sizes: file and line."""
    path = tmp_path / 'h.pcd'
    text = pcd_bytes(_cloud(40), 'ascii').decode().replace(*change)
    path.write_text(text)
    with pytest.raises(FileFormatError, match=r'h\.pcd' + '.*' + words):
        read_pcd(path)


def test_pcd_compressed_sizes_that_cannot_match_are_refused_before_decoding(tmp_path):
    """A size word claiming far more than the LZF bytes can hold is a corrupt file."""
    cloud = _cloud(2000)
    raw = pcd_bytes(cloud, 'binary_compressed')
    at = raw.index(b'DATA binary_compressed\n') + len(b'DATA binary_compressed\n')
    header = raw[:at].replace(b'WIDTH 2000', b'WIDTH 100000000').replace(
        b'POINTS 2000', b'POINTS 100000000')
    sizes = np.array([16, 100000000 * cloud.dtype.itemsize], dtype='<u4').tobytes()
    path = tmp_path / 'bomb.pcd'
    path.write_bytes(header + sizes + b'\x00' * 16)
    with pytest.raises(FileFormatError, match='cannot hold'):
        read_pcd(path)


@pytest.mark.parametrize('old, new, words', [
    ('property float x\n', 'property float\n', ':5: unsupported property'),
    ('property float x\n', 'property\n', ':5: unsupported property'),
    ('property float y\n', 'property float x\n', ":6: property 'x' defined twice"),
    ('element vertex 30\n', 'element vertex -3\n', ':4: bad element count'),
    ('property float x\n', 'property list uchar\n', ':5: malformed list property'),
])
@pytest.mark.parametrize('binary', [True, False])
def test_ply_header_lines_are_checked(tmp_path, old, new, words, binary):
    """PLY property lines without a name, duplicated, or with bad counts: file and line."""
    path = tmp_path / 'h.ply'
    write_ply(path, _cloud(30), binary)
    raw = path.read_bytes()
    assert raw.count(old.encode()) == 1
    path.write_bytes(raw.replace(old.encode(), new.encode()))
    with pytest.raises(FileFormatError, match=r'h\.ply' + words):
        read_ply(path)


def test_failed_write_keeps_the_old_file(tmp_path):
    """A write that fails leaves the previous file untouched and no temporary file."""
    path = tmp_path / 'keep.pcd'
    write_pcd(path, _cloud(10))
    before = path.read_bytes()
    bad = np.zeros(3, dtype=[('x', 'c16')])
    with pytest.raises(ValueError):
        write_pcd(path, bad)
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ['keep.pcd']


@pytest.mark.parametrize('binary', [True, False])
def test_ply_round_trip_and_truncation(tmp_path, binary):
    """PLY ascii and binary_little_endian round trip; a truncated file is reported."""
    cloud = _cloud(50)
    path = tmp_path / 'c.ply'
    write_ply(path, cloud, binary)
    back = read_ply(path)
    for name in cloud.dtype.names:
        np.testing.assert_allclose(back[name], cloud[name], rtol=1e-6)
    path.write_bytes(path.read_bytes()[:-30])
    with pytest.raises(FileFormatError, match='c.ply'):
        read_ply(path)
    assert len(read_cloud_roundtrip(tmp_path, cloud)) == 50


def read_cloud_roundtrip(tmp_path, cloud):
    """Write and read through the extension dispatch."""
    path = tmp_path / 'x.pcd'
    write_cloud(path, cloud, 'binary_compressed')
    return read_cloud(path)


def test_imu_and_pose_csv_errors(tmp_path):
    """Truncated IMU lines and out-of-order poses are reported with their line."""
    imu = tmp_path / 'imu.csv'
    imu.write_text('t,ax,ay,az,gx,gy,gz\n0,0,0,9.8,0,0,0\n0.01,0,0,9.8,0,0\n')
    with pytest.raises(FileFormatError, match=r'imu\.csv:3'):
        read_imu_csv(imu)
    imu.write_text('t,ax,ay,az\n0,0,0,9.8\n0.01,0,0,9.8\n')
    assert read_imu_csv(imu).gyro is None
    poses = PoseStream([0.0, 1.0, 2.0], np.zeros((3, 3)), np.tile([0, 0, 0, 1.0], (3, 1)))
    path = tmp_path / 'poses.csv'
    write_poses_csv(path, poses)
    assert np.allclose(read_poses_csv(path).t, [0, 1, 2])
    lines = path.read_text().splitlines()
    lines[2], lines[3] = lines[3], lines[2]
    path.write_text('\n'.join(lines) + '\n')
    with pytest.raises(FileFormatError, match=r'poses\.csv:4: .*out of order'):
        read_poses_csv(path)
    with pytest.raises(InputError, match='out of order'):
        PoseStream([0.0, 2.0, 1.0], np.zeros((3, 3)), np.tile([0, 0, 0, 1.0], (3, 1)))
    lines[2], lines[3] = lines[3], lines[2]
    lines[2] = ','.join(lines[2].split(',')[:4] + ['1e308', '0', '0', '1'])
    path.write_text('\n'.join(lines) + '\n')
    with warnings.catch_warnings():   # the norm overflowed with a RuntimeWarning
        warnings.simplefilter('error')
        with pytest.raises(FileFormatError, match=r'poses\.csv:3: quaternion norm inf'):
            read_poses_csv(path)


def test_no_time_field_is_a_clear_error():
    """A cloud without per-point time names the fields it has."""
    cloud = make_cloud(np.zeros((3, 3)))
    with pytest.raises(InputError, match='no per-point time field'):
        point_times(cloud)
    assert xyz(cloud).shape == (3, 3)


def test_headers_claiming_huge_points_are_refused_before_allocating(tmp_path):
    """COUNT 300000000 in a 90-byte PCD took 24 GB (killed); 50000 PLY properties took 31 s."""
    from accelcal_ros.lidar.pcd import MAX_VALUES_PER_POINT
    from accelcal_ros.lidar.ply import MAX_PROPERTIES

    path = tmp_path / 'count.pcd'
    for counts, fields in (('300000000', 'x'), ('6000 6000', 'x y')):
        path.write_text(f'VERSION 0.7\nFIELDS {fields}\nSIZE {"4 " * len(fields.split())}\n'
                        f'TYPE {"F " * len(fields.split())}\nCOUNT {counts}\nWIDTH 1\n'
                        'HEIGHT 1\nPOINTS 1\nDATA ascii\n1\n')
        with pytest.raises(FileFormatError, match=f':5: COUNT adds up to more than '
                                                  f'{MAX_VALUES_PER_POINT}'):
            read_pcd(path)   # from the header: nothing allocated
    path.write_text('VERSION 0.7\nFIELDS h\nSIZE 4\nTYPE F\nCOUNT 640\nWIDTH 1\nHEIGHT 1\n'
                    'POINTS 1\nDATA ascii\n' + ' '.join(['0.5'] * 640) + '\n')   # an ESF
    assert read_pcd(path)[0]['h'].shape == (1, 640)
    ply = tmp_path / 'many.ply'
    names = [f'p{k}' for k in range(MAX_PROPERTIES + 1)]
    ply.write_text('ply\nformat ascii 1.0\nelement vertex 1\n'
                   + ''.join(f'property float {n}\n' for n in names) + 'end_header\n'
                   + ' '.join(['1'] * len(names)) + '\n')
    with pytest.raises(FileFormatError, match=f'more than {MAX_PROPERTIES} properties'):
        read_ply(ply)
    ply.write_text('ply\nformat ascii 1.0\nelement vertex 1\n'
                   + ''.join(f'property float {n}\n' for n in names[:-1]) + 'end_header\n'
                   + ' '.join(['1'] * (len(names) - 1)) + '\n')
    assert len(read_ply(ply).dtype.names) == MAX_PROPERTIES
