"""Named views over one mosaic: names, caps, all-or-nothing changes, threads."""
import math
import threading
import time

from accelcal_ros.camera.rig import ring_rig
from accelcal_ros.errors import InputError
from accelcal_ros.panorama import render
from accelcal_ros.panorama.roi_params import ROI_PARAMS
from accelcal_ros.panorama.view_set import (check_view_name, NoSuchView, parse_view_entry,
                                            ViewSet)
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
                         ('a:nan,0,60', 'finite'), ('a:1e308,0,60', 'turns')):
        with pytest.raises(InputError, match=words):
            parse_view_entry(entry)
    spec = next(s for s in ROI_PARAMS if s.name == 'roi_views')
    assert spec.check(['a', 'a:0,0,10'])[1] and 'twice' in spec.check(['a', 'a:0,0,10'])[1]
    many = spec.check(['a', 'b'] + [f'v{k}' for k in range(100)] + ['b', 'a'])[1]
    assert many == 'roi_views: a view name is listed twice: a, b', many   # not all 104
    assert spec.check(['a:0,0,0'])[1] and spec.check(['a', 'b:0,0,60'])[1] is None
    # an unwrapped head-tracker yaw still names a direction; 1e308 deg names none
    assert parse_view_entry('a:-3599970,0,60')[1].degrees()[0] == pytest.approx(30.0)


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


def _two_views(stamp_s):
    """Return (frames, views): views a (0 deg) and b (30 deg) of one frame set at ``stamp_s``."""
    rig = _rig()
    scene = render.make_scene(900, 450, seed=1)
    frames = render.render_camera_views(scene, rig, 0.05, 0.1)
    views = ViewSet(rig, width=160, height=120)
    views.apply_entries(['a:0,0,40', 'b:30,0,40'])
    views.set_frame(frames, 0.05, 0.1, stamp_s)
    return frames, views


def test_render_all_from_one_frame_and_concurrent_steering():
    """Every view renders from the one mosaic while another thread steers them."""
    frames, views = _two_views(12.5)
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


def _run_in_thread(target, *args):
    """Start ``target(*args)`` in a daemon thread; return (thread, result list)."""
    result = []
    thread = threading.Thread(target=lambda: result.append(target(*args)), daemon=True)
    thread.start()
    return thread, result


def test_views_draw_at_once_and_a_new_frame_set_waits_for_the_drawings():
    """
    While a view is drawn, another draws, a pose is taken and a new frame set waits.

    The frame being drawn is never written over. (One lock for the whole set drew one
    view after the other: the second drawing, the pose and the frame set all waited for
    the first.)
    """
    from accelcal_ros.panorama.view import ViewPose

    first, views = _two_views(1.0)
    reference = views.render('a')
    inside, leave = threading.Event(), threading.Event()
    seen = []

    def hold_a():
        with views.drawing('a') as (view, image):
            seen.append((view.pose.degrees(), views.stamp_s, image.copy()))
            inside.set()
            leave.wait(60.0)
            seen.append(image.copy())

    holder, _ = _run_in_thread(hold_a)
    try:
        assert inside.wait(60.0)
        other, drawn = _run_in_thread(views.render, 'b')
        other.join(60.0)
        assert not other.is_alive() and drawn[0].max() > 0   # b drew meanwhile
        steer, _ = _run_in_thread(views.set_pose, 'a', ViewPose.from_degrees(5, 0, 40))
        steer.join(60.0)
        assert not steer.is_alive()   # the pose did not wait for a's drawing
        assert views.pose('a').degrees() == pytest.approx((5, 0, 40))
        assert views.views['a'].pose.degrees() == pytest.approx((0, 0, 40))  # drawn as was
        second = [255 - image for image in first]
        writer, _ = _run_in_thread(views.set_frame, second, 0.05, 0.1, 2.0)
        writer.join(0.3)
        assert writer.is_alive() and views.stamp_s == 1.0   # waits for a's drawing
    finally:
        leave.set()
        holder.join(60.0)
    writer.join(60.0)
    assert not writer.is_alive() and views.stamp_s == 2.0
    assert seen[0][:2] == (pytest.approx((0, 0, 40)), 1.0)
    assert np.array_equal(seen[1], seen[0][2])   # the frame drawn was not written over
    assert np.abs(seen[1].astype(int) - reference).mean() < 1.0   # the first frame set's
    with views.drawing('a') as (view, image):
        assert view.pose.degrees() == pytest.approx((5, 0, 40))  # taken at the next frame
    with pytest.raises(InputError, match='no view'):
        with views.drawing('zzz'):
            pass


def test_a_view_removed_while_its_drawing_waits_is_no_such_view():
    """
    A drawing that waited behind a new frame set for a view removed meanwhile: NoSuchView.

    Every call naming a missing view raises :class:`NoSuchView` (an InputError), so
    the node and the server tell "removed meanwhile" from a real error in one place.
    """
    from accelcal_ros.panorama.view import ViewPose

    frames, views = _two_views(1.0)
    for call in (lambda: views.remove('zzz'), lambda: views.pose('zzz'),
                 lambda: views.set_pose('zzz', ViewPose.from_degrees(0, 0, 40)),
                 lambda: views.render('zzz')):
        with pytest.raises(NoSuchView, match="no view named 'zzz'") as caught:
            call()
        assert isinstance(caught.value, InputError) and caught.value.name == 'zzz'
    inside, leave = threading.Event(), threading.Event()

    def hold_a():
        with views.drawing('a'):
            inside.set()
            leave.wait(60.0)

    holder, _ = _run_in_thread(hold_a)
    try:
        assert inside.wait(60.0)
        writer, _ = _run_in_thread(views.set_frame, frames, 0.05, 0.1, 2.0)
        writer.join(0.2)
        assert writer.is_alive()   # waits for a's drawing

        def draw_b():
            try:
                views.render('b')
            except NoSuchView as exc:
                return exc
            return None

        waiting, outcome = _run_in_thread(draw_b)
        waiting.join(0.2)
        assert waiting.is_alive()  # waits behind the new frame set
        views.remove('b')
    finally:
        leave.set()
        holder.join(60.0)
    writer.join(60.0)
    waiting.join(60.0)
    assert not waiting.is_alive() and isinstance(outcome[0], NoSuchView)
    assert views.names() == ['a'] and set(views.render_all()) == {'a'}


def test_views_drawn_from_many_threads_are_never_torn():
    """
    Views drawn from three threads are each one frame set's, at the pose they report.

    The threads draw over and over while frame sets alternate between an image and its
    negative and the views are steered (16x16 blocks against that frame set drawn alone).
    """
    from accelcal_ros.panorama.view import LevelledView, ViewPose

    rig = _rig()
    scene = render.make_scene(900, 450, seed=1)
    frames = render.render_camera_views(scene, rig, 0.05, 0.1)
    sets = {0.0: frames, 1.0: [255 - image for image in frames]}
    poses = [ViewPose.from_degrees(az, 0, 40) for az in (-30, -20, 0, 10, 30, 40)]
    views = ViewSet(rig, width=160, height=120)
    views.apply_entries([f'v{i}:{-30 + 30 * i},0,40' for i in range(3)])
    views.set_frame(sets[0.0], 0.05, 0.1, 0.0)
    stop = threading.Event()
    drawn, errors = [], []

    def draw(name):
        try:
            for _ in range(40):
                with views.drawing(name) as (view, image):
                    drawn.append((views.stamp_s, view.pose, image.copy()))
        except Exception as exc:  # noqa: B902 - reported below
            errors.append(exc)

    def churn():
        k = 0
        while not stop.is_set():
            k += 1
            views.set_frame(sets[float(k % 2)], 0.05, 0.1, float(k % 2))
            views.set_pose(f'v{k % 3}', poses[k % len(poses)])

    threads = [threading.Thread(target=draw, args=(f'v{i}',), daemon=True) for i in range(3)]
    changer = threading.Thread(target=churn, daemon=True)
    changer.start()
    for t in threads:
        t.start()
    for t in threads:
        t.join(120.0)
    stop.set()
    changer.join(60.0)
    assert not errors and len(drawn) == 120
    assert len({stamp for stamp, _, _ in drawn}) == 2   # both frame sets were drawn
    mosaic = views.mosaic
    truth = {}
    for stamp, pose, image in drawn:
        key = (stamp, pose.degrees())
        if key not in truth:
            alone = LevelledView(rig, mosaic.layout, 160, 120, pose)
            alone.set_attitude(0.05, 0.1)
            for i, camera_image in enumerate(sets[stamp]):
                mosaic.set_image(i, camera_image)
            truth[key] = alone.render(mosaic.image).astype(np.float32)
        diff = np.abs(image.astype(np.float32) - truth[key]).mean(axis=2)
        blocks = diff[:112].reshape(7, 16, 10, 16).mean(axis=(1, 3))
        assert blocks.max() < 4.0, (stamp, pose.degrees(), blocks.max())


@pytest.mark.parametrize('busy', ['writer', 'readers'])
def test_frame_lock_starves_neither_side(busy):
    """
    Against a side that asks again at once, the other side's 200 turns all come.

    A writer-first lock kept two readers out for minutes against a looping writer.
    """
    from accelcal_ros.panorama.view_set import FrameLock

    lock = FrameLock()
    stop = threading.Event()
    inside = {'readers': 0, 'writing': 0, 'overlaps': 0}
    guard = threading.Lock()

    def read(turns):
        k = 0
        while (k < turns) if turns else not stop.is_set():
            with lock.reading():
                with guard:
                    inside['readers'] += 1
                    inside['overlaps'] += inside['writing']
                time.sleep(0.001)   # a drawing takes a while
                with guard:
                    inside['readers'] -= 1
            k += 1

    def write(turns):
        k = 0
        while (k < turns) if turns else not stop.is_set():
            with lock.writing():
                with guard:
                    inside['overlaps'] += inside['readers'] + inside['writing']
                    inside['writing'] += 1
                time.sleep(0.001)   # so does copying a frame set in
                with guard:
                    inside['writing'] -= 1
            k += 1

    hot = [threading.Thread(target=write, args=(0,), daemon=True)] if busy == 'writer' else \
        [threading.Thread(target=read, args=(0,), daemon=True) for _ in range(2)]
    turns = [threading.Thread(target=read, args=(200,), daemon=True) for _ in range(2)] \
        if busy == 'writer' else [threading.Thread(target=write, args=(200,), daemon=True)]
    for t in hot + turns:
        t.start()
    for t in turns:
        t.join(60.0)
    done = not any(t.is_alive() for t in turns)
    stop.set()
    for t in hot:
        t.join(60.0)
    assert done and inside['overlaps'] == 0
