"""
``accelcal rig-calibrate BAG``: still poses found in one recording equal the directory path.

Ten rendered poses of the 3-camera ring at 400x300 are recorded as a continuous bag: the
IMU (100 Hz) swings between poses (a changing gravity direction, shaking, and a turn on
the gyro) and holds still 2 s per pose; the cameras record a grey frame set while moving
and three sets per still pose (the pose's images in the middle, noisier copies near the
ends, cameras a few ms apart). The same images and still IMU samples written as a
capture directory give the reference calibration.
"""
import os

from accelcal_ros.camera.rig import load_rig
from accelcal_ros.cli import main
from accelcal_ros.recording.sim_bags import bag_path, T0_NS
from accelcal_ros.recording.writer import BagWriter, sensor_data_qos
from accelcal_ros.rig.bag import camera_name, camera_names
from accelcal_ros.rig.extrinsics import rotation_angle_deg
from accelcal_ros.rig.render import (default_truth, imu_samples, plan_poses, Renderer,
                                     write_imu_csv)
from accelcal_ros.textformats import load_yaml_mapping
import cv2
import numpy as np
import pytest

TRUTH = default_truth(width=400, height=300, focal_px=212.0)
TOPICS = [f'/{name}/image_raw' for name in TRUTH.names]
RATE_HZ = 100.0
MOVE_S = 1.0
STILL_S = 2.0
ARGS = ['--board', '11x8', '--square-m', '0.025']


def _motion(f_from, f_to, rng):
    """Specific force (m/s^2) and rate (rad/s) of the swing from one pose to the next."""
    n = int(MOVE_S * RATE_HZ)
    s = (np.arange(n) + 0.5) / n
    envelope = np.sin(np.pi * s)[:, None]
    f = (1 - s)[:, None] * f_from + s[:, None] * f_to
    f = f + 3.0 * envelope * np.sin(2 * np.pi * 3.0 * s)[:, None] * np.array([1.0, -0.6, 0.3])
    gyro = 0.8 * envelope * np.array([0.2, -0.5, 1.0]) + rng.normal(0, 0.002, (n, 3))
    return f, gyro


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    """Render once; write the capture directory, an mcap bag (gyro) and a ROS 1 bag (no gyro)."""
    root = tmp_path_factory.mktemp('rig_bag')
    rng = np.random.default_rng(4)
    renderer = Renderer(TRUTH)
    poses = plan_poses(TRUTH, 10)
    events = []     # (t_s, kind, payload)
    t = 0.0
    previous = TRUTH.gravity_m_s2 * np.array([0.0, 0.0, 1.0])
    for k, pose in enumerate(poses):
        images = [renderer.render(pose, i, 1.0, rng) for i in range(len(TRUTH.names))]
        still = imu_samples(TRUTH, pose, rng, duration_s=STILL_S, rate_hz=RATE_HZ,
                            noise_m_s2=0.01)
        folder = root / 'dir' / f'pose{k:02d}'
        folder.mkdir(parents=True)
        for name, image in zip(TRUTH.names, images):
            cv2.imwrite(str(folder / f'{name}.png'), image)
        write_imu_csv(str(folder / 'imu.csv'), still)
        f_move, g_move = _motion(previous, still['a'][0], rng)
        previous = still['a'][-1]
        for j in range(len(f_move)):
            events.append((t + j / RATE_HZ, 'imu', (f_move[j], g_move[j])))
        grey = [np.full_like(image, 110) for image in images]
        events.append((t + 0.5 * MOVE_S, 'set', grey))
        t += MOVE_S
        gyro_still = rng.normal(0.0, 0.001, (len(still['t']), 3))
        for j, ts in enumerate(still['t']):
            events.append((t + ts, 'imu', (still['a'][j], gyro_still[j])))
        noisy = [np.clip(im + rng.normal(0, 2.0, im.shape), 0, 255).astype(np.uint8)
                 for im in images]
        events.append((t + 0.35, 'set', noisy))
        events.append((t + 0.5 * STILL_S, 'set', images))
        events.append((t + STILL_S - 0.35, 'set', noisy))
        t += STILL_S
    events.sort(key=lambda e: e[0])
    bags = {}
    for fmt, with_gyro in (('mcap', True), ('ros1', False)):
        path = bag_path(root, 'rig', fmt)
        with BagWriter(path, fmt) as writer:
            writer.add_topic('/imu/data_raw', 'sensor_msgs/Imu', [sensor_data_qos()])
            for topic in TOPICS:
                writer.add_topic(topic, 'sensor_msgs/Image')
            writer.add_topic('/cam0/camera_info', 'sensor_msgs/CameraInfo')
            for ts, kind, payload in events:
                ns = T0_NS + int(round(ts * 1e9))
                if kind == 'imu':
                    writer.write('/imu/data_raw', ns, writer.imu_message(
                        ns, payload[0], 'imu_link', payload[1] if with_gyro else None))
                    continue
                for i, (topic, image) in enumerate(zip(TOPICS, payload)):
                    stamp = ns + i * 3_000_000
                    writer.write(topic, stamp + 1_000_000,
                                 writer.image_message(stamp, image, f'{TRUTH.names[i]}_optical'))
        bags[fmt] = path
    out = root / 'dir_rig.yaml'
    assert main(['rig-calibrate', str(root / 'dir')] + ARGS + ['-o', str(out)]) == 0
    return root, bags, out


@pytest.mark.parametrize('fmt', ['mcap', 'ros1'])
def test_bag_equals_directory(recording, fmt, tmp_path, capsys):
    """Same K, D (same images); rotations and board tilt within 0.003 deg; the truth met."""
    root, bags, reference = recording
    out = tmp_path / 'rig.yaml'
    export = tmp_path / 'capture'
    assert main(['rig-calibrate', str(bags[fmt])] + ARGS
                + ['-o', str(out), '--export', str(export)]) == 0
    printed = capsys.readouterr()
    assert 'camera cam1: /cam1/image_raw' in printed.out
    assert 'pose09: still' in printed.out
    assert ('carries no angular rate' in printed.err) == (fmt == 'ros1')
    assert sorted(p.name for p in export.iterdir()) == [f'pose{k:02d}' for k in range(10)]
    for k in range(10):   # the middle set of each still period, not a noisy or grey one
        for name in TRUTH.names:
            chosen = cv2.imread(str(export / f'pose{k:02d}' / f'{name}.png'),
                                cv2.IMREAD_GRAYSCALE)
            expected = cv2.imread(str(root / 'dir' / f'pose{k:02d}' / f'{name}.png'),
                                  cv2.IMREAD_GRAYSCALE)
            assert np.array_equal(chosen, expected)
    got, ref = load_rig(out), load_rig(reference)
    assert got.names == ref.names == TRUTH.names
    for a, b in zip(got.cameras, ref.cameras):
        assert np.allclose(a.model.K, b.model.K, rtol=0, atol=1e-9)
        assert np.allclose(a.model.D, b.model.D, rtol=0, atol=1e-12)
        assert rotation_angle_deg(a.R, b.R) < 0.003   # R_0i (same images) with imu_to_camera
    assert rotation_angle_deg(got.imu_to_camera, ref.imu_to_camera) < 0.003
    assert rotation_angle_deg(got.imu_to_camera, TRUTH.imu_to_camera) < 0.2
    report = load_yaml_mapping(str(out)[:-5] + '_report.yaml')
    ref_report = load_yaml_mapping(str(reference)[:-5] + '_report.yaml')
    assert report['imu_to_camera']['poses'] == ref_report['imu_to_camera']['poses'] == 10
    assert abs(report['board_tilt']['tilt_deg'] - ref_report['board_tilt']['tilt_deg']) < 0.003


def test_camera_names_from_topics():
    """``/cam0/image_raw`` -> cam0; compressed and nested names; clashes keep the topic."""
    assert camera_name('/cam0/image_raw') == 'cam0'
    assert camera_name('/rig/left/image_raw/compressed') == 'left'
    assert camera_name('front') == 'front'
    assert camera_names(['/a/cam/image_raw', '/b/cam/image_raw']) == [
        'a_cam_image_raw', 'b_cam_image_raw']


def _small_bag(path, fmt, moving=False, sizes=((40, 30), (40, 30))):
    """Two still periods (or constant shaking) with one 'cam0' image each."""
    rng = np.random.default_rng(0)
    with BagWriter(path, fmt) as writer:
        writer.add_topic('/imu', 'sensor_msgs/Imu')
        writer.add_topic('/cam0/image_raw', 'sensor_msgs/Image')
        t = np.arange(0, 7.0, 0.01)
        accel = np.tile([0.0, 0.0, 9.81], (len(t), 1)) + rng.normal(0, 0.01, (len(t), 3))
        shake = (np.abs(t - 3.5) < 0.5) | moving
        accel[shake] += 3.0 * np.sin(2 * np.pi * 4 * t[shake])[:, None]
        events = [(ti, None) for ti in t] + [(1.5, sizes[0]), (5.5, sizes[1])]
        for ti, size in sorted(events, key=lambda e: e[0]):
            ns = T0_NS + int(round(ti * 1e9))
            if size is None:
                writer.write('/imu', ns, writer.imu_message(ns, accel[int(round(ti * 100))],
                                                            'imu_link'))
            else:
                writer.write('/cam0/image_raw', ns, writer.image_message(
                    ns, np.full(size[::-1], 100, np.uint8), 'cam0_optical'))
    return path


def _run(bag, tmp_path, *extra):
    out = tmp_path / 'rig.yaml'
    status = main(['rig-calibrate', str(bag)] + ARGS + ['-o', str(out)] + list(extra))
    assert not out.exists()
    return status


def test_bad_recordings(tmp_path, capsys):
    """No still pose; a missing topic (listed); a camera changing resolution; no board."""
    moving = _small_bag(bag_path(tmp_path, 'moving', 'mcap'), 'mcap', moving=True)
    assert _run(moving, tmp_path) != 0
    assert 'no still pose found' in capsys.readouterr().err
    sizes = _small_bag(bag_path(tmp_path, 'sizes', 'sqlite3'), 'sqlite3',
                       sizes=((40, 30), (64, 48)))
    assert _run(sizes, tmp_path, '--images', '/cam1/image_raw') != 0
    err = capsys.readouterr().err
    assert 'no topic /cam1/image_raw' in err and '/cam0/image_raw (sensor_msgs/Image' in err
    assert _run(sizes, tmp_path, '--imu', '/cam0/image_raw') != 0
    assert 'not sensor_msgs/Imu' in capsys.readouterr().err
    assert _run(sizes, tmp_path) != 0
    err = capsys.readouterr().err
    assert '/cam0/image_raw: images of different sizes (40x30, then 64x48' in err
    same = _small_bag(bag_path(tmp_path, 'same', 'mcap'), 'mcap')
    assert _run(same, tmp_path) != 0
    assert 'no 11x8 board found in any image of poses pose00, pose01' in capsys.readouterr().err


def test_export_is_checked_first_and_left_only_by_a_success(tmp_path, capsys):
    """--export inside the input bag is refused before anything is made; a failure leaves none."""
    bag = _small_bag(bag_path(tmp_path, 'same', 'mcap'), 'mcap')
    before = sorted(os.listdir(bag))
    assert _run(bag, tmp_path, '--export', os.path.join(bag, 'capture')) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'is inside' in err and 'an input of the command' in err
    assert sorted(os.listdir(bag)) == before
    export = tmp_path / 'new' / 'capture'          # its parent is made by the run, too
    assert _run(bag, tmp_path, '--export', str(export)) != 0
    assert 'no 11x8 board found' in capsys.readouterr().err
    assert not (tmp_path / 'new').exists()
    (tmp_path / 'taken').mkdir()
    assert _run(bag, tmp_path, '--export', str(tmp_path / 'taken')) == 1
    assert 'exists; name a new folder' in capsys.readouterr().err
