"""``accelcal stitch`` and ``accelcal study horizon`` end to end, with bad inputs."""
import math
import os

from accelcal_ros.camera.rig import ring_rig, save_rig
from accelcal_ros.cli import main
from accelcal_ros.panorama import render
from accelcal_ros.panorama.projection import PanoramaGeometry
import cv2
import numpy as np
import pytest


@pytest.fixture(scope='module')
def setup(tmp_path_factory):
    """Write a 3-camera rig and its rendered images; return (folder, image paths, scene)."""
    folder = tmp_path_factory.mktemp('stitch')
    rig = ring_rig(3, 320, 240, 275.0, 45.0, distortion=(-0.08, 0.01, 0, 0, 0))
    save_rig(folder / 'rig.yaml', rig)
    scene = render.make_scene(1800, 900, seed=5)
    views = render.render_camera_views(scene, rig, math.radians(-3), math.radians(8))
    paths = []
    for i, view in enumerate(views):
        paths.append(str(folder / f'cam{i}.png'))
        cv2.imwrite(paths[-1], view)
    return folder, paths, scene


def test_stitch_writes_a_faithful_panorama(setup, capsys):
    """The written PNG matches the scene over the covered area; horizon at (H-1)/2."""
    folder, paths, scene = setup
    out = folder / 'pano.png'
    code = main(['stitch', '--rig', str(folder / 'rig.yaml'), '--roll', '-3', '--pitch', '8',
                 '--width', '720', '--height', '480', '-o', str(out), *paths])
    assert code == 0 and 'horizon at row 239.5' in capsys.readouterr().out
    panorama = cv2.imread(str(out))
    geometry = PanoramaGeometry(720, 480)
    truth = render.render_panorama_truth(scene, geometry)
    covered = panorama.max(axis=2) > 0
    assert render.psnr(panorama, truth, covered) > 28.0
    rows = render.horizon_rows(panorama, geometry)
    assert np.nanmax(np.abs(rows - 239.5)) < 0.5


def test_stitch_cylindrical_and_grey(setup):
    """Grey inputs give a grey panorama; the cylindrical projection is accepted."""
    folder, paths, _ = setup
    grey = []
    for p in paths:
        g = p.replace('.png', '_grey.png')
        cv2.imwrite(g, cv2.imread(p, cv2.IMREAD_GRAYSCALE))
        grey.append(g)
    out = folder / 'cyl.png'
    assert main(['stitch', '--rig', str(folder / 'rig.yaml'), '--roll', '0', '--pitch', '0',
                 '--width', '400', '--height', '300', '--projection', 'cylindrical',
                 '--fov-v', '100', '-o', str(out), *grey]) == 0
    image = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)
    assert image.shape == (300, 400)


@pytest.mark.parametrize('case, words', [
    ('count', 'rig has 3 cameras'), ('size', r"camera 1 \('cam1'\).*the rig file says"),
    ('missing', 'image not found'), ('rig', r'missing key\(s\) K'),
    ('notimage', 'not an image'), ('nan', 'finite'), ('fov', 'fov.v'),
    ('twice', 'is given for cameras cam0 and cam2')])
def test_stitch_bad_input_exits_2_and_writes_nothing(setup, tmp_path, capsys, case, words):
    """Every bad input is one clear line, status 2, and no output file."""
    folder, paths, _ = setup
    rig = str(folder / 'rig.yaml')
    images = list(paths)
    extra = []
    if case == 'count':
        images = images[:2]
    elif case == 'size':
        cv2.imwrite(str(tmp_path / 'small.png'), np.zeros((100, 100, 3), np.uint8))
        images[1] = str(tmp_path / 'small.png')
    elif case == 'missing':
        images[2] = str(tmp_path / 'nope.png')
    elif case == 'rig':
        (tmp_path / 'bad.yaml').write_text(
            'cameras:\n- {name: a, width: 320, height: 240, R: [1,0,0,0,1,0,0,0,1]}\n')
        rig = str(tmp_path / 'bad.yaml')
    elif case == 'notimage':
        (tmp_path / 'text.png').write_text('hello')
        images[0] = str(tmp_path / 'text.png')
    elif case == 'nan':
        extra = ['--roll', 'nan']
    elif case == 'fov':
        extra = ['--fov-v', '200']
    elif case == 'twice':   # one file for two cameras: was stitched, status 0
        images[2] = os.path.join(os.path.dirname(images[0]), '.', os.path.basename(images[0]))
    out = tmp_path / 'out.png'
    args = ['stitch', '--rig', rig, '--roll', '0', '--pitch', '0', '--width', '360',
            '--height', '240', *extra, '-o', str(out), *images]
    assert main(args) == (2 if case in ('nan', 'fov') else 1)  # 2: a usage error
    err = capsys.readouterr().err
    assert err.startswith('accelcal: error:') and len(err.strip().splitlines()) == 1
    import re
    assert re.search(words, err), err
    assert not out.exists()


def test_study_horizon_quick(capsys):
    """``accelcal study horizon --quick`` prints the paper comparison and our figures."""
    assert main(['study', 'horizon', '--quick', '--count', '3']) == 0
    out = capsys.readouterr().out
    assert 'paper' in out and '+2.0 deg' in out and 'own calibration' in out


def test_a_failed_folder_output_removes_what_it_made_and_nothing_else(tmp_path):
    """A run that fails mid-way left frame_000000.png... and new folders behind."""
    import os

    from accelcal_ros.panorama.bag import FrameSink

    frame = np.zeros((8, 16, 3), np.uint8)
    sink = FrameSink(tmp_path / 'a' / 'b' / 'frames', 10.0)
    sink.write(frame)
    sink.write(frame)
    assert len(os.listdir(tmp_path / 'a' / 'b' / 'frames')) == 2
    sink.close(ok=False)
    assert not (tmp_path / 'a').exists()
    (tmp_path / 'mine').mkdir()                  # an empty folder of the user's stays
    sink = FrameSink(tmp_path / 'mine', 10.0)
    sink.write(frame)
    (tmp_path / 'mine' / 'notes.txt').write_text('kept')
    sink.close(ok=False)
    assert os.listdir(tmp_path / 'mine') == ['notes.txt']
    sink = FrameSink(tmp_path / 'ok', 10.0)      # a success keeps its frames
    sink.write(frame)
    sink.close()
    assert os.listdir(tmp_path / 'ok') == ['frame_000000.png']
