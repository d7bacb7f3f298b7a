"""Named views over one mosaic: names, caps, all-or-nothing changes, threads."""
import math
import threading

from accelcal_ros.camera.rig import ring_rig
from accelcal_ros.errors import InputError
from accelcal_ros.panorama import render
from accelcal_ros.panorama.roi_params import ROI_PARAMS
from accelcal_ros.panorama.view_set import check_view_name, parse_view_entry, ViewSet
import numpy as np
import pytest


def _rig():
    return ring_rig(3, 320, 240, 275.0, 45.0)


@pytest.mark.parametrize('name', ['front', 'cam_2', 'A1b'])
def test_valid_names(name):
    """Letters, digits and single underscores, starting with a letter."""
    assert check_view_name(name) == name


@pytest.mark.parametrize('name', ['', '1st', 'a/b', 'a b', 'a__b', '_a', 'a_', 'ä', 'x' * 49,
                                  None])
def test_names_that_are_not_topic_tokens_are_refused(name):
    """Anything that would not make roi/<name>/image a valid topic name."""
    with pytest.raises(InputError, match='view name'):
        check_view_name(name)


def test_entries_parse_and_bad_entries_say_why():
    """NAME or NAME:AZ,EL,FOV in degrees; a bad fov or a missing number is refused."""
    name, pose = parse_view_entry('left:-40,5,30')
    assert name == 'left' and pose.degrees() == pytest.approx((-40, 5, 30))
    assert parse_view_entry('top') == ('top', None)
    for entry, words in (('a:1,2', 'expected'), ('a:1,2,180', 'fov_h'), ('a:x,0,60', 'numbers'),
                         ('a:nan,0,60', 'finite')):
        with pytest.raises(InputError, match=words):
            parse_view_entry(entry)
    spec = next(s for s in ROI_PARAMS if s.name == 'roi_views')
    assert spec.check(['a', 'a:0,0,10'])[1] and 'twice' in spec.check(['a', 'a:0,0,10'])[1]
    assert spec.check(['a:0,0,0'])[1] and spec.check(['a', 'b:0,0,60'])[1] is None


def test_cap_and_all_or_nothing_changes():
    """One view over the cap is refused; a bad request changes nothing; others keep going."""
    views = ViewSet(_rig(), max_views=3, width=64, height=48)
    assert views.apply_entries(['a', 'b:10,0,40']) == (['a', 'b'], [])
    views.add('c')
    with pytest.raises(InputError, match='at most 3'):
        views.add('d')
    with pytest.raises(InputError, match='view name'):
        views.apply_entries(['a', 'bad name'])
    with pytest.raises(InputError, match='at most 3'):
        views.apply_entries(['a', 'b', 'c', 'd'])
    assert views.names() == ['a', 'b', 'c']
    assert views.apply_entries(['b', 'e:0,0,20']) == (['e'], ['a', 'c'])
    assert views.views['b'].pose.degrees() == pytest.approx((10, 0, 40))
    with pytest.raises(InputError, match='no view'):
        views.remove('a')


def test_render_all_from_one_frame_and_concurrent_steering():
    """Every view renders from the one mosaic while another thread steers them."""
    rig = _rig()
    scene = render.make_scene(900, 450, seed=1)
    frames = render.render_camera_views(scene, rig, 0.05, 0.1)
    views = ViewSet(rig, width=160, height=120)
    views.apply_entries(['a:0,0,40', 'b:30,0,40'])
    views.set_frame(frames, 0.05, 0.1, 12.5)
    stop = threading.Event()
    errors = []

    def steer():
        from accelcal_ros.panorama.view import ViewPose

        k = 0
        while not stop.is_set():
            k += 1
            try:
                views.set_pose('a', ViewPose(math.radians(k % 20), 0.0, math.radians(40)))
            except InputError as exc:  # pragma: no cover - would be a bug
                errors.append(exc)

    thread = threading.Thread(target=steer)
    thread.start()
    try:
        for _ in range(20):
            out = views.render_all()
            assert set(out) == {'a', 'b'} and out['a'][0].shape == (120, 160, 3)
            assert out['b'][0].max() > 0
    finally:
        stop.set()
        thread.join()
    assert not errors
    with pytest.raises(InputError, match='expected 3 images'):
        views.set_frame(frames[:2], 0.0, 0.0)
    with pytest.raises(InputError, match='finite'):
        views.set_frame(frames, math.nan, 0.0)
    assert views.attitude == (0.05, 0.1)
    assert np.array_equal(views.render('b'), views.render('b'))


def test_views_posed_alike_share_a_frame_and_planes_serve_every_view():
    """Two views posed alike draw one frame; each frame matches its view drawn alone."""
    from accelcal_ros.panorama.view import LevelledView, ViewPose

    rig = _rig()
    scene = render.make_scene(900, 450, seed=1)
    views = ViewSet(rig, width=160, height=120)
    views.apply_entries(['a:10,0,40', 'b:10,0,40', 'c:-20,2,50'])
    assert views.views['a'].planes is views.views['c'].planes  # one set of planes
    for k, (roll, pitch) in enumerate([(0.05, 0.1), (-0.02, 0.12)]):
        frames = render.render_camera_views(scene, rig, roll, pitch)
        views.set_frame(frames, roll, pitch)
        shared = views.shared_frames
        out = views.render_all()
        assert views.shared_frames == shared + 1  # b copied a's frame of this frame set
        assert np.array_equal(out['a'][0], out['b'][0])
        for name, pose in (('a', ViewPose.from_degrees(10, 0, 40)),
                           ('c', ViewPose.from_degrees(-20, 2, 50))):
            alone = LevelledView(rig, views.mosaic.layout, 160, 120, pose)
            alone.set_attitude(roll, pitch)
            assert np.array_equal(out[name][0], alone.render(views.mosaic.image))
    views.set_pose('b', ViewPose.from_degrees(11, 0, 40))  # moved: drawn on its own
    shared = views.shared_frames
    out = views.render_all()
    assert views.shared_frames == shared and not np.array_equal(out['a'][0], out['b'][0])
