"""
Bounded fuzz test of every file reader: a damaged file parses or raises an AccelcalError.

Each reader (recording, calibration, rig, camera_info, boresight, pose and IMU CSV/YAML
files, PCD ascii/binary/binary_compressed, PLY ascii/binary, IMU bags as mcap and ROS 1, a
rosbag2 directory's metadata.yaml) gets a valid file written by the package's own writer
(checked to load), then ``CASES`` mutations of it drawn with a fixed seed: bytes flipped,
inserted or deleted, truncation, non-UTF-8 bytes, a number replaced by a huge one / NaN /
infinity / text / nothing, lines deleted, duplicated or swapped, header counts changed, an
empty file. Any other exception, or a case running past ``CASE_LIMIT_S`` (a hang), fails the
test, which prints how to reproduce each case.

``ACCELCAL_FUZZ_CASES=N`` runs N cases per reader (default 150) to hunt further; running
this file as a script prints the time per reader.
"""
import contextlib
import importlib
import os
import random
import re
import signal
import threading
import time
import warnings

from accelcal_ros.errors import AccelcalError
import numpy as np
import pytest

CASES = int(os.environ.get('ACCELCAL_FUZZ_CASES', '150'))
SEED = 20261123
CASE_LIMIT_S = 20.0  # a reader that takes longer on a small file hangs
_NUMBER = re.compile(rb'-?\d+(\.\d+)?(e-?\d+)?')
_REPLACEMENTS = [b'1e999', b'-1e999', b'1e308', b'-1e308', b'1e-320', b'99999999999999999999',
                 b'-1', b'0', b'nan', b'NaN', b'inf', b'-inf', b'.nan', b'.inf', b'abc', b'',
                 b'\xff\xfe', b'0x10', b'1,2', b'[1, 2]', b'{a: 1}', b'4294967297', b'-0']


def _function(*candidates):
    """Return the first importable ``module:function`` of ``candidates`` (modules move)."""
    for spec in candidates:
        module, name = spec.split(':')
        try:
            return getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError):
            continue
    raise ImportError(f'none of {candidates} found')


# ---------------------------------------------------------------------------------------
# valid files, one per reader


def _write_recording(path):
    save = _function('accelcal_ros.sensor.recording:save_recording',
                     'accelcal_ros.driver.replay:save_recording')
    t = np.arange(12) * 0.01
    save(path, t, np.tile([0.1, -0.2, 9.81], (12, 1)))


def _write_calibration(path):
    from accelcal_ros.fileio import write_text_atomic
    from accelcal_ros.textformats import dump_yaml

    write_text_atomic(path, dump_yaml({
        'model': 'full', 'scale': [1.01, 0.99, 1.002], 'bias': [0.01, -0.02, 0.003],
        'misalignment': [0.001, -0.002, 0.0005], 'scale_std': [0.001, 0.001, 0.001],
        'bias_std': [0.001, 0.001, 0.001], 'misalignment_std': [1e-4, 1e-4, 1e-4],
        'residual_rms_g': 0.001, 'positions': 12, 'predicted_tilt_error_deg': 0.05}))


def _write_rig(path):
    from accelcal_ros.fileio import write_text_atomic
    from accelcal_ros.textformats import dump_yaml

    k = [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0]
    eye = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    yaw = [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    write_text_atomic(path, dump_yaml({'cameras': [
        {'name': 'cam0', 'width': 640, 'height': 480, 'K': k, 'D': [0.01, -0.02, 0, 0, 0],
         'R': eye},
        {'name': 'cam1', 'width': 640, 'height': 480, 'K': k, 'D': [0, 0, 0, 0, 0],
         'R': yaw}]}))


def _write_camera_info(path):
    from accelcal_ros.fileio import write_text_atomic

    write_text_atomic(path, (
        'image_width: 640\nimage_height: 480\ncamera_name: cam0\n'
        'camera_matrix:\n  rows: 3\n  cols: 3\n  data: [500, 0, 320, 0, 500, 240, 0, 0, 1]\n'
        'distortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n'
        '  data: [0.01, -0.02, 0, 0, 0]\n'))


def _write_boresight(path):
    from accelcal_ros.fileio import write_text_atomic
    from accelcal_ros.textformats import dump_yaml

    write_text_atomic(path, dump_yaml({'rpy_deg': [1.5, -0.5, 90.0],
                                       'rpy_std_deg': [0.01, 0.01, 0.02]}))


def _write_trajectory(path):
    from accelcal_ros.fileio import write_text_atomic

    rows = [f'{t:.2f},{55.75 + 1e-5 * t:.9f},{37.6 + 2e-5 * t:.9f},150.0,1.0,-2.0,{30 + t:.1f}'
            for t in np.arange(0.0, 2.0, 0.1)]
    write_text_atomic(path, 't,lat,lon,h,roll,pitch,yaw\n' + '\n'.join(rows) + '\n')


def _write_poses(path):
    from accelcal_ros.lidar.poses import PoseStream, write_poses_csv

    t = np.arange(8) * 0.1
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (8, 1))
    write_poses_csv(path, PoseStream(t, np.column_stack([t, t * 0, t * 0]), quat))


def _write_odometry(path):
    rows = ['t,v,yaw_rate'] + [f'{0.02 * k:.2f},{5.0 + 0.1 * k:.3f},{0.01 * k:.3f}'
                               for k in range(8)]
    with open(path, 'w') as handle:
        handle.write('\n'.join(rows) + '\n')


def _write_imu(path):
    from accelcal_ros.lidar.imu_log import ImuLog, write_imu_csv

    t = np.arange(10) * 0.005
    write_imu_csv(path, ImuLog(t, np.tile([0.0, 0.1, 9.8], (10, 1)),
                               np.tile([0.001, 0.0, -0.001], (10, 1))))


def _write_view_path(path):
    rows = ['t,azimuth,elevation,fov_h'] + [f'{0.5 * k:.1f},{10.0 * k - 20:.1f},{k - 3:.1f},60'
                                            for k in range(8)]
    with open(path, 'w') as handle:
        handle.write('\n'.join(rows) + '\n')


def _cloud():
    from accelcal_ros.lidar.cloud import make_cloud

    rng = np.random.default_rng(1)
    return make_cloud(rng.normal(size=(40, 3)), rng.uniform(0, 100, 40), np.arange(40) % 16,
                      np.linspace(0, 0.1, 40))


def _pcd_writer(data):
    def write(path):
        from accelcal_ros.lidar.pcd import write_pcd

        write_pcd(path, _cloud(), data)
    return write


def _ply_writer(binary):
    def write(path):
        from accelcal_ros.lidar.ply import write_ply

        write_ply(path, _cloud(), binary)
    return write


def _bag_writer(fmt):
    def write(path):
        import shutil

        from accelcal_ros.recording.sim_bags import write_imu_bag

        target = path + '.src' + ('.bag' if fmt == 'ros1' else '')
        shutil.rmtree(target, ignore_errors=True)
        t = np.arange(20) * 0.01
        write_imu_bag(target, fmt, t, np.tile([0.0, 0.1, 9.8], (20, 1)))
        if os.path.isdir(target):  # rosbag2: the one storage file of the directory
            target = os.path.join(target, [f for f in os.listdir(target)
                                           if f.endswith('.mcap')][0])
        shutil.copyfile(target, path)
    return write


def _write_bag_metadata(path):
    """Write a rosbag2 directory (mcap) whose metadata.yaml is the fuzzed file."""
    import shutil

    from accelcal_ros.recording.sim_bags import write_imu_bag

    directory = os.path.dirname(path)
    shutil.rmtree(directory, ignore_errors=True)
    t = np.arange(20) * 0.01
    write_imu_bag(directory, 'mcap', t, np.tile([0.0, 0.1, 9.8], (20, 1)))


def _read_bag_directory(path):
    """Read the IMU topic of the bag directory that holds ``path``."""
    return _read_imu_bag(os.path.dirname(path))


def _read_imu_bag(path):
    from accelcal_ros.recording.bag import BagReader
    from accelcal_ros.recording.streams import read_imu

    with BagReader(path) as bag:
        return read_imu(bag, None)


def _read_camera_info(path):
    from accelcal_ros.camera.camera_info import load_camera_info

    return load_camera_info(path)


def _read_pcd(path):
    from accelcal_ros.lidar.pcd import read_pcd

    return read_pcd(path)


def _read_ply(path):
    from accelcal_ros.lidar.ply import read_ply

    return read_ply(path)


READERS = {
    'recording_csv': ('rec.csv', _write_recording, lambda p: _function(
        'accelcal_ros.sensor.recording:load_recording',
        'accelcal_ros.driver.replay:load_recording')(p)),
    'calibration_yaml': ('calib.yaml', _write_calibration, lambda p: _function(
        'accelcal_ros.sensor.calibration_file:load_calibration',
        'accelcal_ros.calibration.calibration_file:load_calibration')(p)),
    'rig_yaml': ('rig.yaml', _write_rig,
                 lambda p: _function('accelcal_ros.camera.rig:load_rig')(p)),
    'camera_info_yaml': ('cam.yaml', _write_camera_info, _read_camera_info),
    'rig_intrinsics_yaml': ('cam.yaml', _write_camera_info, lambda p: _function(
        'accelcal_ros.rig.intrinsics:load_camera_info')(p)),
    'view_path_csv': ('path.csv', _write_view_path, lambda p: _function(
        'accelcal_ros.panorama.view_cli:ViewPath').load(p)),
    'boresight_yaml': ('bs.yaml', _write_boresight,
                       lambda p: _function('accelcal_ros.lidar.boresight:load_boresight')(p)),
    'poses_csv': ('poses.csv', _write_poses,
                  lambda p: _function('accelcal_ros.lidar.poses:read_poses_csv')(p)),
    'trajectory_csv': ('traj.csv', _write_trajectory, lambda p: _function(
        'accelcal_ros.lidar.geotraj:read_trajectory_csv')(p)),
    'odometry_csv': ('odo.csv', _write_odometry, lambda p: _function(
        'accelcal_ros.sensor.tilt_series:read_odometry_csv')(p)),
    'imu_log_csv': ('imu.csv', _write_imu,
                    lambda p: _function('accelcal_ros.lidar.imu_log:read_imu_csv')(p)),
    'pcd_ascii': ('a.pcd', _pcd_writer('ascii'), _read_pcd),
    'pcd_binary': ('b.pcd', _pcd_writer('binary'), _read_pcd),
    'pcd_binary_compressed': ('c.pcd', _pcd_writer('binary_compressed'), _read_pcd),
    'ply_ascii': ('a.ply', _ply_writer(False), _read_ply),
    'ply_binary': ('b.ply', _ply_writer(True), _read_ply),
    'imu_bag_mcap': ('imu.mcap', _bag_writer('mcap'), _read_imu_bag),
    'imu_bag_ros1': ('imu.bag', _bag_writer('ros1'), _read_imu_bag),
    'bag_metadata_yaml': (os.path.join('bag', 'metadata.yaml'), _write_bag_metadata,
                          _read_bag_directory),
}


# ---------------------------------------------------------------------------------------
# mutations


def _header_end(data):
    for marker in (b'end_header\n', b'\nDATA '):
        at = data.find(marker)
        if at >= 0:
            return data.find(b'\n', at + 1) + 1 if marker != b'end_header\n' else \
                at + len(marker)
    return len(data)


def mutate(data, rng):
    """Return ``(damaged bytes, description)`` of one random mutation of ``data``."""
    n = len(data)
    kind = rng.choice(['flip', 'flip_header', 'truncate', 'non_utf8', 'number', 'number',
                       'number_header', 'delete_line', 'duplicate_line', 'swap_lines',
                       'insert_bytes', 'delete_bytes', 'empty', 'append', 'several'])
    if kind == 'several':
        for _ in range(rng.randint(2, 4)):
            data, _ = mutate(data, rng)
        return data, 'several mutations'
    if kind == 'empty' or not n:
        return b'', 'empty file'
    if kind in ('flip', 'flip_header'):
        out = bytearray(data)
        limit = max(1, _header_end(data)) if kind == 'flip_header' else n
        for _ in range(rng.randint(1, 8)):
            k = rng.randrange(limit)
            out[k] = rng.randrange(256)
        return bytes(out), f'{kind}'
    if kind == 'truncate':
        k = rng.randrange(n)
        return data[:k], f'truncated at byte {k} of {n}'
    if kind == 'non_utf8':
        k = rng.randrange(n + 1)
        junk = rng.choice([b'\xff', b'\xfe\xff', b'\x80\x81', b'\xc3', b'\xed\xa0\x80', b'\x00'])
        return data[:k] + junk + data[k:], f'{junk!r} inserted at byte {k}'
    if kind in ('number', 'number_header'):
        region = data[:_header_end(data)] if kind == 'number_header' else data
        matches = list(_NUMBER.finditer(region))
        if not matches:
            return data + b'\n1e999\n', 'number appended'
        match = rng.choice(matches)
        new = rng.choice(_REPLACEMENTS)
        return data[:match.start()] + new + data[match.end():], \
            f'number {match.group()!r} at byte {match.start()} -> {new!r}'
    lines = data.split(b'\n')
    if kind == 'delete_line' and len(lines) > 1:
        k = rng.randrange(len(lines))
        return b'\n'.join(lines[:k] + lines[k + 1:]), f'line {k + 1} deleted'
    if kind == 'duplicate_line':
        k = rng.randrange(len(lines))
        return b'\n'.join(lines[:k + 1] + lines[k:]), f'line {k + 1} duplicated'
    if kind == 'swap_lines' and len(lines) > 2:
        i, j = sorted(rng.sample(range(len(lines)), 2))
        lines[i], lines[j] = lines[j], lines[i]
        return b'\n'.join(lines), f'lines {i + 1} and {j + 1} swapped'
    if kind == 'insert_bytes':
        k = rng.randrange(n + 1)
        junk = bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
        return data[:k] + junk + data[k:], f'{len(junk)} random bytes inserted at {k}'
    if kind == 'delete_bytes':
        k = rng.randrange(n)
        m = rng.randint(1, 32)
        return data[:k] + data[k + m:], f'{m} bytes deleted at {k}'
    return data + bytes(rng.randrange(256) for _ in range(20)), 'garbage appended'


class _Hang(Exception):
    """A case ran past CASE_LIMIT_S (reported as a failure)."""


@contextlib.contextmanager
def _time_limit(seconds):
    """Raise :class:`_Hang` after ``seconds`` (main thread on POSIX; else no limit)."""
    if not hasattr(signal, 'setitimer') or threading.current_thread() is not \
            threading.main_thread():
        yield
        return

    def expired(signum, frame):
        raise _Hang(f'no answer within {seconds} s')

    previous = signal.signal(signal.SIGALRM, expired)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def run_reader(name, folder, cases=CASES):
    """Fuzz one reader; return ``(failures, seconds)`` (failures: reproducer lines)."""
    filename, write, read = READERS[name]
    path = os.path.join(folder, filename)
    write(path)
    read(path)  # the undamaged file must load, or the fuzzing means nothing
    with open(path, 'rb') as handle:
        valid = handle.read()
    rng = random.Random(f'{SEED}-{name}')
    failures = []
    start = time.perf_counter()
    for case in range(cases):
        damaged, what = mutate(valid, rng)
        with open(path, 'wb') as handle:
            handle.write(damaged)
        try:
            with warnings.catch_warnings(), _time_limit(CASE_LIMIT_S):
                warnings.simplefilter('ignore', RuntimeWarning)  # e.g. NaN cast to int
                read(path)
        except AccelcalError:
            pass
        except Exception as exc:  # noqa: B902 - what the test hunts
            failures.append(f'{name} case {case} ({what}): {type(exc).__name__}: {exc}\n'
                            f'    file bytes: {damaged[:400]!r}'
                            + (' ...' if len(damaged) > 400 else ''))
    return failures, time.perf_counter() - start


@pytest.mark.parametrize('name', sorted(READERS))
def test_damaged_files_parse_or_raise_accelcal_error(tmp_path, name):
    """CASES seeded mutations of a valid file: each parses or raises an AccelcalError."""
    failures, _ = run_reader(name, str(tmp_path))
    assert not failures, (f'{len(failures)} of {CASES} damaged files raised something '
                          'other than AccelcalError:\n' + '\n'.join(failures[:10]))


@pytest.mark.parametrize('name', sorted(READERS))
def test_directory_missing_and_unreadable_paths_raise_accelcal_error(tmp_path, name):
    """A directory, a missing file, an unreadable one and an empty path: AccelcalError."""
    _, _, read = READERS[name]
    for path in (str(tmp_path), str(tmp_path / 'missing.file'), '/proc/self/mem', ''):
        with pytest.raises(AccelcalError):
            read(path)


COMMAND_CASES = max(CASES // 6, 1)
#: commands run on a damaged input X (the other inputs valid): exit 0 or 1, one line, no bug
COMMANDS = {
    'recording_csv': ['apply', 'X', '--calibration', 'calib.yaml', '-o', 'out.csv'],
    'calibration_yaml': ['plot-calibration', 'X', '-o', 'out.png'],
    'rig_yaml': ['stitch', '--rig', 'X', '--roll', '1', '--pitch', '2', '--width', '64',
                 '--height', '32', '-o', 'out.png', 'img0.png', 'img1.png'],
    'boresight_yaml': ['georeference', '--cloud', 'b.pcd', '--poses', 'poses.csv',
                       '--boresight', 'X', '-o', 'out.pcd'],
    'poses_csv': ['georeference', '--cloud', 'b.pcd', '--poses', 'X', '--boresight',
                  'bs.yaml', '-o', 'out.pcd'],
    'pcd_binary_compressed': ['georeference', '--cloud', 'X', '--poses', 'poses.csv',
                              '--boresight', 'bs.yaml', '-o', 'out.ply'],
}


def _calibration_with_captures(path):
    """Write a calibration file as ``accelcal calibrate`` does (with captures to plot)."""
    from accelcal_ros.fileio import write_text_atomic
    from accelcal_ros.textformats import dump_yaml

    directions = np.array([[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0],
                           [0, -1, 0.0]])
    write_text_atomic(path, dump_yaml({
        'model': 'full', 'scale': [1.01, 0.99, 1.002], 'bias': [0.01, -0.02, 0.003],
        'misalignment': [0.001, -0.002, 0.0005], 'positions': 6,
        'predicted_tilt_error_deg': 0.05, 'residual_rms_g': 0.001, 'dropped_positions': [],
        'captures_g': (directions * 1.01).tolist(),
        'residuals_g': [0.001, -0.002, 0.0005, 0.0, 0.001, -0.001]}))


@pytest.mark.parametrize('name', sorted(COMMANDS))
def test_commands_on_damaged_inputs_fail_with_one_line(tmp_path, monkeypatch, capsys, name):
    """`accelcal` on a damaged input: status 0 or 1 and at most one error line, no bug."""
    import cv2

    from accelcal_ros.cli import main

    monkeypatch.chdir(tmp_path)
    _calibration_with_captures('calib.yaml')
    for reader, path in (('poses_csv', 'poses.csv'), ('boresight_yaml', 'bs.yaml'),
                         ('pcd_binary_compressed', 'b.pcd')):
        READERS[reader][1](path)
    for k in range(2):
        cv2.imwrite(f'img{k}.png', np.full((480, 640, 3), 100 + 50 * k, np.uint8))
    filename, write, _ = READERS[name]
    write(filename)
    if name == 'calibration_yaml':
        _calibration_with_captures(filename)
    argv = [filename if a == 'X' else a for a in COMMANDS[name]]
    damaged_argv = ['damaged' + os.path.splitext(filename)[1] if a == 'X' else a
                    for a in COMMANDS[name]]
    assert main(argv) == 0, capsys.readouterr().err  # the undamaged input works
    with open(filename, 'rb') as handle:
        valid = handle.read()
    rng = random.Random(f'{SEED}-command-{name}')
    failures = []
    for case in range(COMMAND_CASES):
        damaged, what = mutate(valid, rng)
        with open(damaged_argv[damaged_argv.index('damaged' + os.path.splitext(filename)[1])],
                  'wb') as handle:
            handle.write(damaged)
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', RuntimeWarning)
            status = main(damaged_argv)
        err = capsys.readouterr().err.strip().splitlines()
        errors = [line for line in err if 'error:' in line]
        if status not in (0, 1) or len(errors) > 1 or any('internal error' in e for e in err):
            failures.append(f'{name} case {case} ({what}): status {status}: {err[-1:]}\n'
                            f'    file bytes: {damaged[:300]!r}')
    assert not failures, '\n'.join(failures[:10])


def main():
    """Print cases and time per reader (``python test/test_fuzz_readers.py``)."""
    import tempfile

    total = 0.0
    with tempfile.TemporaryDirectory() as folder:
        for name in sorted(READERS):
            failures, seconds = run_reader(name, folder)
            total += seconds
            print(f'{name:24} {CASES:5d} cases {seconds:7.2f} s  {len(failures)} failures')
            for line in failures[:3]:
                print('   ', line)
    print(f'{"all readers":24} {CASES * len(READERS):5d} cases {total:7.2f} s')


if __name__ == '__main__':
    main()
