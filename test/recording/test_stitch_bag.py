"""accelcal stitch BAG: a levelled panorama per recorded frame set (folder and video)."""
import math

from accelcal_ros.camera.rig import ring_rig, save_rig
from accelcal_ros.cli import main
from accelcal_ros.frames import specific_force_from_roll_pitch
from accelcal_ros.panorama import render
from accelcal_ros.panorama.projection import PanoramaGeometry
from accelcal_ros.recording.sim_bags import bag_path, T0_NS
from accelcal_ros.recording.writer import BagWriter
import cv2
import numpy as np
import pytest

TOPICS = ['/cam0/image_raw', '/cam1/image_raw', '/cam2/image_raw']
FRAMES = 4


def _attitude(k):
    return math.radians(-3.0 + 2.0 * k), math.radians(6.0 - 3.0 * k)


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    """Record a 3-camera rig swinging in roll/pitch, with its attitude and IMU."""
    root = tmp_path_factory.mktemp('stitch')
    rig = ring_rig(3, 320, 240, 275.0, 45.0, distortion=(-0.08, 0.01, 0, 0, 0))
    save_rig(root / 'rig.yaml', rig)
    scene = render.make_scene(1800, 900, seed=5)
    bag = bag_path(root, 'rig', 'mcap')
    with BagWriter(bag) as writer:
        for topic in TOPICS:
            writer.add_topic(topic, 'sensor_msgs/Image')
        writer.add_topic('/attitude', 'geometry_msgs/Vector3Stamped')
        writer.add_topic('/imu/data_raw', 'sensor_msgs/Imu')
        for k in range(FRAMES):
            ns = T0_NS + k * 100_000_000
            roll, pitch = _attitude(k)
            for j in range(-25 if k == 0 else -2, 3):   # IMU at 50 Hz, swinging steadily
                t_imu = ns + j * 20_000_000
                roll_imu, pitch_imu = _attitude(k + j / 5.0)
                force = specific_force_from_roll_pitch(roll_imu, pitch_imu) * 9.80665
                writer.write('/imu/data_raw', t_imu, writer.imu_message(t_imu, force, 'imu'))
            writer.write('/attitude', ns, writer.vector3_stamped_message(ns, (roll, pitch, 0),
                                                                         'imu'))
            views = render.render_camera_views(scene, rig, roll, pitch)
            for i, (topic, view) in enumerate(zip(TOPICS, views)):
                # triggered together (one stamp), received 3 ms apart
                writer.write(topic, ns + i * 3_000_000, writer.image_message(ns, view,
                                                                             f'cam{i}'))
    return root, bag, scene


@pytest.mark.parametrize('source', ('--attitude', '--imu'))
def test_stitch_bag_to_folder_levels_every_frame(recording, source, tmp_path, capsys):
    """Each frame matches the levelled scene truth; horizon at (H-1)/2 despite the swing."""
    root, bag, scene = recording
    out = tmp_path / 'frames'
    topic = '/attitude' if source == '--attitude' else '/imu/data_raw'
    assert main(['stitch', str(bag), '--rig', str(root / 'rig.yaml'), '--images', *TOPICS,
                 source, topic, '--width', '720', '--height', '480', '-o', str(out)]) == 0
    assert f'{FRAMES} panoramas' in capsys.readouterr().out
    files = sorted(out.iterdir())
    assert len(files) == FRAMES
    geometry = PanoramaGeometry(720, 480)
    truth = render.render_panorama_truth(scene, geometry)
    for path in files:
        panorama = cv2.imread(str(path))
        covered = panorama.max(axis=2) > 0
        assert render.psnr(panorama, truth, covered) > 26.0
        deviation = np.abs(render.horizon_rows(panorama, geometry) - 239.5)
        # unlevelled, the 2-6 deg swing would move the horizon by 8-24 px
        assert np.nanmedian(deviation) < 0.3 and np.nanpercentile(deviation, 90) < 1.0


def test_stitch_bag_video_and_bad_topics(recording, tmp_path, capsys):
    """An .mp4 holds one frame per set; a wrong topic count is refused, nothing written."""
    root, bag, _ = recording
    video = tmp_path / 'pano.mp4'
    assert main(['stitch', str(bag), '--rig', str(root / 'rig.yaml'), '--images', *TOPICS,
                 '--attitude', '/attitude', '--width', '360', '--height', '240',
                 '-o', str(video)]) == 0
    capture = cv2.VideoCapture(str(video))
    count = 0
    while capture.read()[0]:
        count += 1
    assert count == FRAMES
    bad = tmp_path / 'bad.mp4'
    assert main(['stitch', str(bag), '--rig', str(root / 'rig.yaml'), '--images', TOPICS[0],
                 '--attitude', '/attitude', '-o', str(bad)]) != 0
    assert '1 --images topic(s) for a rig of 3 cameras' in capsys.readouterr().err
    assert not bad.exists()
    # no --images at all: said "1 --images topic(s)" when none was given
    assert main(['stitch', str(bag), '--rig', str(root / 'rig.yaml'), '--attitude',
                 '/attitude', '-o', str(bad)]) != 0
    assert 'give --images TOPIC ... for a BAG' in capsys.readouterr().err
    assert not bad.exists()
    for name in ('pano.png', 'pano.gif'):   # one image's name: refused, no folder made
        assert main(['stitch', str(bag), '--rig', str(root / 'rig.yaml'), '--images', *TOPICS,
                     '--attitude', '/attitude', '-o', str(tmp_path / name)]) != 0
        assert 'a recording gives many frames' in capsys.readouterr().err
        assert not (tmp_path / name).exists()


def test_an_attitude_topic_with_impossible_samples(tmp_path, capsys):
    """NaN, inf and 1e300 roll/pitch were passed on (serve started, then refused each tab)."""
    from accelcal_ros.errors import InputError
    from accelcal_ros.recording.bag import BagReader
    from accelcal_ros.recording.streams import read_attitude

    def bag_of(name, values):
        path = bag_path(tmp_path, name, 'mcap')
        with BagWriter(path) as writer:
            writer.add_topic('/attitude', 'geometry_msgs/Vector3Stamped')
            for k, (roll, pitch) in enumerate(values):
                ns = T0_NS + k * 100_000_000
                writer.write('/attitude', ns,
                             writer.vector3_stamped_message(ns, (roll, pitch, 0), 'imu'))
        return path

    mixed = bag_of('mixed', [(0.1, 0.2), (math.nan, 0.0), (0.0, math.inf), (1e300, 0.0),
                             (-0.1, -0.2)])
    with BagReader(mixed) as bag:
        att = read_attitude(bag, '/attitude')
    assert np.allclose(att.roll, [0.1, -0.1]) and np.allclose(att.pitch, [0.2, -0.2])
    assert any('3 of 5 samples' in w and 'skipped' in w for w in att.warnings)
    bad = bag_of('bad', [(math.nan, 0.0), (0.0, 1e300)])
    with BagReader(bad) as bag:
        with pytest.raises(InputError, match='no usable roll/pitch: all 2 samples'):
            read_attitude(bag, '/attitude')


@pytest.mark.parametrize('extra, words', [
    (['--attitude', '/attitude', '--imu', '/imu/data_raw'], 'not both'),
    (['--attitude', '/attitude', '--calibration', 'CAL'], '--calibration corrects'),
])
def test_an_attitude_source_that_would_be_ignored_is_refused(recording, tmp_path, capsys,
                                                             extra, words):
    """--imu beside --attitude (or --calibration with --attitude) was silently ignored."""
    root, bag, _ = recording
    cal = tmp_path / 'cal.yaml'
    cal.write_text('model: diagonal\nscale: [1, 1, 1]\nbias: [0, 0, 0]\n')
    extra = [str(cal) if e == 'CAL' else e for e in extra]
    out = tmp_path / 'frames'
    assert main(['stitch', str(bag), '--rig', str(root / 'rig.yaml'), '--images', *TOPICS,
                 *extra, '-o', str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and words in err, err
    assert not out.exists()
