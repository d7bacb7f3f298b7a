"""``accelcal view`` (images and bag, with a path), ``serve`` and ``study roi`` end to end."""
import math
import select
import signal
import socket
import subprocess
import sys
import urllib.error
import urllib.parse
import urllib.request

from accelcal_ros.camera.rig import ring_rig, save_rig
from accelcal_ros.cli import main
from accelcal_ros.panorama import render
from accelcal_ros.panorama.roi_study import closed_form_horizon, render_view_truth
from accelcal_ros.panorama.view import ViewPose
from accelcal_ros.recording.sim_bags import bag_path, T0_NS
from accelcal_ros.recording.writer import BagWriter
import cv2
import numpy as np
import pytest

TOPICS = ['/cam0/image_raw', '/cam1/image_raw', '/cam2/image_raw']
FRAMES = 4


@pytest.fixture(scope='module')
def setup(tmp_path_factory):
    """Write a 3-camera rig, its rendered images and a bag of a swinging rig."""
    folder = tmp_path_factory.mktemp('view')
    rig = ring_rig(3, 320, 240, 275.0, 45.0, distortion=(-0.08, 0.01, 0, 0, 0))
    save_rig(folder / 'rig.yaml', rig)
    scene = render.make_scene(1800, 900, seed=5)
    views = render.render_camera_views(scene, rig, math.radians(-3), math.radians(8))
    paths = []
    for i, view in enumerate(views):
        paths.append(str(folder / f'cam{i}.png'))
        cv2.imwrite(paths[-1], view)
    bag = bag_path(folder, 'rig', 'mcap')
    with BagWriter(bag) as writer:
        for topic in TOPICS:
            writer.add_topic(topic, 'sensor_msgs/Image')
        writer.add_topic('/attitude', 'geometry_msgs/Vector3Stamped')
        for k in range(FRAMES):
            ns = T0_NS + k * 100_000_000
            roll, pitch = math.radians(-3.0 + 2.0 * k), math.radians(6.0 - 3.0 * k)
            writer.write('/attitude', ns, writer.vector3_stamped_message(ns, (roll, pitch, 0),
                                                                         'imu'))
            for i, (topic, image) in enumerate(zip(TOPICS, render.render_camera_views(
                    scene, rig, roll, pitch))):
                writer.write(topic, ns + i * 3_000_000, writer.image_message(ns, image,
                                                                             f'cam{i}'))
    return folder, paths, scene, bag


def test_view_writes_the_scenes_pinhole_view(setup, capsys):
    """The PNG matches the scene's own view; K, coverage and the horizon row are said."""
    folder, paths, scene, _ = setup
    out = folder / 'view.png'
    code = main(['view', '--rig', str(folder / 'rig.yaml'), '--roll', '-3', '--pitch', '8',
                 '--azimuth', '20', '--elevation', '2', '--fov-h', '50', '--width', '400',
                 '--height', '300', '-o', str(out), *paths])
    said = capsys.readouterr().out
    assert code == 0 and '400x300 view' in said and '% covered' in said
    f = 200 / math.tan(math.radians(25))
    assert f'fx = fy = {f:.2f} px' in said
    assert f'horizon at row {149.5 + f * math.tan(math.radians(2)):.2f}' in said
    image = cv2.imread(str(out))
    truth = render_view_truth(scene, 400, 300, ViewPose.from_degrees(20, 2, 50))
    covered = cv2.erode((image.max(axis=2) > 0).astype(np.uint8), np.ones((5, 5), np.uint8))
    assert covered.mean() > 0.5
    assert render.psnr(image, truth, covered.astype(bool)) > 33.0


def test_view_looking_straight_up_says_the_horizon_is_not_in_view(setup, tmp_path, capsys):
    """Elevation 90 deg: "horizon not in view" (it said "horizon at row 1.8e19")."""
    folder, paths, _, _ = setup
    assert main(['view', '--rig', str(folder / 'rig.yaml'), '--roll', '-3', '--pitch', '8',
                 '--elevation', '90', '--width', '64', '--height', '48', '-o',
                 str(tmp_path / 'up.png'), *paths]) == 0
    said = capsys.readouterr().out
    assert said.endswith('horizon not in view\n') and 'horizon at row' not in said


def _serve_args(folder, paths, *extra):
    return ['serve', '--rig', str(folder / 'rig.yaml'), '--roll', '-3', '--pitch', '8',
            '--width', '64', '--height', '48', *extra, *paths]


def test_serve_says_the_port_it_listens_on_and_a_link_that_opens(setup):
    """
    ``--port 0``: the port picked, said once listening; the token percent-encoded.

    It said ``http://127.0.0.1:0/``, and ``--token 'a+b&c#d é'`` as is: the link's token
    ended at the ``&`` (the rest a fragment), so the page answered 401.
    """
    pytest.importorskip('aiohttp', reason='aiohttp is not installed')
    folder, paths, _, _ = setup
    run = 'import sys\nfrom accelcal_ros.cli import main\nsys.exit(main(sys.argv[1:]))\n'
    proc = subprocess.Popen([sys.executable, '-c', run, *_serve_args(
        folder, paths, '--port', '0', '--token', 'a+b&c#d é')], stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True)
    try:
        assert select.select([proc.stdout], [], [], 120.0)[0], 'nothing said in 120 s'
        line = proc.stdout.readline()
        assert line.startswith('serving 1 frame set(s)'), line
        url = line.split(' on ', 1)[1].split(' ', 1)[0]
        parts = urllib.parse.urlsplit(url)
        assert parts.hostname == '127.0.0.1' and parts.port not in (None, 0), url
        assert not parts.fragment and \
            urllib.parse.parse_qs(parts.query) == {'token': ['a+b&c#d é']}, url
        with urllib.request.urlopen(url, timeout=30) as page:
            assert page.status == 200 and 'WebSocket' in page.read().decode()
        with pytest.raises(urllib.error.HTTPError, match='401'):
            urllib.request.urlopen(url.split('?')[0], timeout=30)
    finally:
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0 and 'Traceback' not in err, err


@pytest.mark.parametrize('host', ['127.0.0.1', 'nonexistent.invalid'])
def test_serve_that_cannot_listen_is_one_line_naming_the_address(setup, capsys, host):
    """
    A port in use or a host that does not resolve: one error naming host:port, status 1.

    It said "serving ... on http://host:port/" first (before binding), then only
    "Name or service not known" or asyncio's "error while attempting to bind".
    """
    pytest.importorskip('aiohttp', reason='aiohttp is not installed')
    folder, paths, _, _ = setup
    with socket.socket() as busy:
        busy.bind(('127.0.0.1', 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        code = main(_serve_args(folder, paths, '--host', host, '--port', str(port)))
    out, err = capsys.readouterr()
    assert code == 1 and 'serving' not in out, (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(
        f'accelcal: error: cannot listen on {host}:{port}: '), err
    if host == '127.0.0.1':
        assert lines[0].endswith('Address already in use'), err


def test_view_over_a_bag_follows_the_path(setup, tmp_path, capsys):
    """One frame per set; frame k shows the path's pose at its time, levelled."""
    folder, _, scene, bag = setup
    path = tmp_path / 'path.csv'
    path.write_text('t,azimuth,elevation,fov_h\n0,-20,0,60\n0.3,25,3,40\n')
    out = tmp_path / 'frames'
    assert main(['view', str(bag), '--rig', str(folder / 'rig.yaml'), '--images', *TOPICS,
                 '--attitude', '/attitude', '--width', '320', '--height', '240',
                 '--path', str(path), '-o', str(out)]) == 0
    said = capsys.readouterr().out
    assert f'{FRAMES} views 320x240 along' in said and f'{FRAMES} lookup rebuilds' in said
    files = sorted(out.iterdir())
    assert len(files) == FRAMES
    for k, file in enumerate(files):
        s = min(1.0, 0.1 * k / 0.3)
        pose = ViewPose.from_degrees(-20 + 45 * s, 3 * s, 60 - 20 * s)
        image = cv2.imread(str(file))
        truth = render_view_truth(scene, 320, 240, pose)
        covered = cv2.erode((image.max(axis=2) > 0).astype(np.uint8),
                            np.ones((5, 5), np.uint8)).astype(bool)
        assert covered.mean() > 0.5 and render.psnr(image, truth, covered) > 30.0, k


@pytest.mark.parametrize('extra, words', [
    (['--fov-h', '180'], 'fov-h'), (['--fov-h', '0'], 'fov-h'), (['--fov-h', 'nan'], 'fov-h'),
    (['--azimuth', 'inf'], 'azimuth'), (['--width', '100000'], 'width'),
    (['--height', '4'], 'height')])
def test_view_bad_options_exit_2_and_write_nothing(setup, tmp_path, capsys, extra, words):
    """Out-of-range fov, non-finite direction or a size past the cap: usage error."""
    folder, paths, _, _ = setup
    out = tmp_path / 'v.png'
    code = main(['view', '--rig', str(folder / 'rig.yaml'), '--roll', '0', '--pitch', '0',
                 '-o', str(out), *extra, *paths])
    assert code == 2 and words in capsys.readouterr().err and not out.exists()


def test_view_bad_path_and_missing_attitude(setup, tmp_path, capsys):
    """A path with fov 190 names its row; image files without --roll are refused."""
    folder, paths, _, bag = setup
    path = tmp_path / 'path.csv'
    path.write_text('t,azimuth,elevation,fov_h\n0,0,0,60\n1,0,0,190\n')
    assert main(['view', str(bag), '--rig', str(folder / 'rig.yaml'), '--images', *TOPICS,
                 '--attitude', '/attitude', '--path', str(path), '-o',
                 str(tmp_path / 'o')]) == 1
    err = capsys.readouterr().err
    assert 'row 2' in err and 'fov_h' in err and not (tmp_path / 'o').exists()
    assert main(['view', '--rig', str(folder / 'rig.yaml'), '-o', str(tmp_path / 'v.png'),
                 *paths]) == 1
    assert '--roll' in capsys.readouterr().err


@pytest.mark.parametrize('command', ['stitch', 'view', 'serve'])
def test_an_option_the_input_would_ignore_is_refused(setup, tmp_path, capsys, command):
    """--roll on a bag (its attitude is the bag's), --imu/--fps on image files: refused."""
    folder, paths, _, bag = setup
    rig = ['--rig', str(folder / 'rig.yaml')]
    out = [] if command == 'serve' else ['-o', str(tmp_path / 'out.png')]
    bag_args = [str(bag), *rig, '--images', *TOPICS, '--attitude', '/attitude']
    for argv, words in (([*bag_args, '--roll', '30', '--pitch', '30'], '--roll and --pitch'),
                        ([*bag_args, '--pitch', '5'], '--pitch is not read for a BAG'),
                        ([*rig, '--roll', '0', '--pitch', '0', '--imu', '/imu', *paths],
                         '--imu is not read for image files'),
                        ([*rig, '--roll', '0', '--pitch', '0', '--fps', '5', *paths],
                         '--fps is not read for image files')):
        assert main([command, *argv, *out]) == 1, argv
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and words in err, err
    assert not (tmp_path / 'out.png').exists()


def test_study_roi_quick(capsys, tmp_path):
    """The false roll follows 2 deg x sin(azimuth); the rendering agrees with the closed form."""
    out = tmp_path / 'roi.json'
    assert main(['study', 'roi', '--quick', '--count', '3', '--json', str(out)]) == 0
    said = capsys.readouterr().out
    assert 'false roll up to 1.7' in said and 'own calibration (3 fits' in said
    import json

    table = json.loads(out.read_text())['azimuths']
    for row in table:
        az = math.radians(row['azimuth_deg'])
        assert abs(row['true']['roll_deg']) < 0.02 and abs(row['true']['offset_px']) < 0.3
        for name in ('-2', '+2'):
            cell = row[name]
            assert abs(cell['roll_deg'] - cell['closed_form_roll_deg']) < 0.02
            assert abs(cell['offset_px'] - cell['closed_form_offset_px']) < 0.3
            assert abs(abs(cell['roll_deg']) - 2.0 * abs(math.sin(az))) < 0.05
    roll, offset = closed_form_horizon(640, 360, ViewPose.from_degrees(90.0, 0.0, 60.0),
                                       (0.0, 0.2), (0.0, 0.2))
    assert abs(roll) < 1e-9 and abs(offset) < 1e-9


@pytest.mark.parametrize('text', [
    '', 't,azimuth,elevation,fov_h\n', 't,azimuth,elevation\n0,1,2\n',
    't,azimuth,elevation,fov_h\n0,nan,0,60\n', 't,azimuth,elevation,fov_h\n0,x,0,60\n',
    't,azimuth,elevation,fov_h\n1,0,0,60\n0,0,0,60\n', 't,azimuth,elevation,fov_h\n0,0,0,60\n1,0',
    't,azimuth,elevation,fov_h\n0,1e308,0,60\n0.5,0,1e308,60\n', b'\xff\xfe\x00t,az\n'])
def test_damaged_path_files_are_one_clear_error(tmp_path, text):
    """A path CSV that is empty, short, non-numeric, unordered or out of range: AccelcalError."""
    from accelcal_ros.errors import AccelcalError
    from accelcal_ros.panorama.view_cli import ViewPath

    path = tmp_path / 'path.csv'
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(AccelcalError):
        ViewPath.load(str(path))


def test_path_interpolates_and_unwraps_azimuth():
    """179 -> -179 deg turns by 2 deg through 180, not by 358 deg through 0."""
    from accelcal_ros.panorama.view_cli import ViewPath

    path = ViewPath([0.0, 1.0], [179.0, -179.0], [0.0, 10.0], [60.0, 40.0])
    assert path.at(0.5).degrees() == pytest.approx((-180.0, 5.0, 50.0))
    assert path.at(-3).degrees() == pytest.approx((179.0, 0.0, 60.0))
    assert path.at(9).degrees() == pytest.approx((-179.0, 10.0, 40.0))
