"""The stitcher's frame-set policy without ROS: sets, stalls, attitude waits, time jumps."""
import math
import threading

from accelcal_ros.panorama.frame_sets import FrameSetPolicy, FrameSetWorker
import pytest

SETTINGS = {'sync_tolerance_s': 0.02, 'stale_timeout_s': 1.0, 'attitude_tolerance_s': 0.5,
            'attitude_wait_s': 0.05}


class Log:
    """Collect the policy's log lines."""

    def __init__(self):
        self.lines = []

    def __call__(self, level, text):
        self.lines.append((level, text))

    def count(self, words):
        return sum(words in text for _, text in self.lines)


def _policy(n=3, **settings):
    log = Log()
    return FrameSetPolicy([f'cam{i}' for i in range(n)], {**SETTINGS, **settings}, log), log


def _feed(policy, stamp, now, cameras=(0, 1, 2), attitude=(0.1, 0.2)):
    for i in cameras:
        policy.add_frame(i, stamp, f'img{i}@{stamp:.2f}', now)
    if attitude is not None:
        policy.add_attitude(stamp, *attitude, now)


def test_a_complete_set_is_stitched_once_with_its_attitude():
    """Frames within the tolerance form a set, stitched once; older sets never again."""
    policy, log = _policy()
    _feed(policy, 10.0, 100.0)
    frame_set = policy.poll(100.0)
    assert frame_set.stamp_s == 10.0 and frame_set.images == ['img0@10.00', 'img1@10.00',
                                                              'img2@10.00']
    assert (frame_set.roll_rad, frame_set.pitch_rad) == (0.1, 0.2)
    assert policy.poll(100.0) is None
    # camera 1 is 15 ms late (within 20 ms): still one set, stamped with the newest
    _feed(policy, 10.1, 100.1, cameras=(0, 2))
    policy.add_frame(1, 10.115, 'late', 100.1)
    assert policy.poll(100.1) is None and policy.retry   # the attitude of 10.115 may come
    frame_set = policy.poll(100.16)
    assert frame_set.stamp_s == pytest.approx(10.115) and frame_set.images[1] == 'late'


def test_no_attitude_then_waiting_for_the_attitude_of_the_instant():
    """Nothing before the first attitude (said once); a late attitude is waited for."""
    policy, log = _policy()
    _feed(policy, 10.0, 100.0, attitude=None)
    assert policy.poll(100.0) is None and policy.status == 'no attitude yet'
    _feed(policy, 10.1, 100.1, attitude=None)
    assert policy.poll(100.1) is None
    assert log.count('no attitude received yet') == 1
    policy.add_attitude(10.05, 0.0, 0.0, 100.1)
    _feed(policy, 10.2, 100.2, attitude=None)
    assert policy.poll(100.2) is None and policy.retry          # waits for 10.2's attitude
    policy.add_attitude(10.2, 0.3, 0.4, 100.21)
    frame_set = policy.poll(100.21)
    assert frame_set.stamp_s == 10.2 and frame_set.roll_rad == 0.3
    # no newer attitude within attitude_wait_s: the nearest within the tolerance is used
    _feed(policy, 10.3, 100.3, attitude=None)
    assert policy.poll(100.3) is None
    assert policy.poll(100.36).roll_rad == 0.3
    # none within attitude_tolerance_s: skipped, said once
    _feed(policy, 11.0, 101.0, attitude=None)
    assert policy.poll(101.0) is None and policy.poll(101.1) is None
    assert log.count('no attitude within 0.5 s') == 1


def test_a_stalled_camera_is_left_out_and_comes_back():
    """A camera silent for stale_timeout_s is left out (None), said once, then back."""
    policy, log = _policy()
    _feed(policy, 10.0, 100.0)
    assert policy.poll(100.0) is not None
    for k in range(1, 15):
        _feed(policy, 10.0 + 0.1 * k, 100.0 + 0.1 * k, cameras=(0, 1))
        frame_set = policy.poll(100.0 + 0.1 * k)
        if k <= 10:
            assert frame_set is None                  # waits for camera 2 while it is live
        else:
            assert frame_set.images[2] is None and frame_set.images[0] is not None
    assert log.count('cam2 stalled') == 1 and policy.cameras(101.5)[2].stalled
    _feed(policy, 11.5, 101.5)
    assert policy.poll(101.5).images[2] == 'img2@11.50'
    assert log.count('cam2 is back') == 1


def test_unmatched_stamps_are_reported_once_with_the_offsets():
    """Cameras whose stamps never meet within the tolerance: one line with the offsets."""
    policy, log = _policy(n=2)
    for k in range(40):
        policy.add_attitude(10 + 0.1 * k, 0.0, 0.0, 100 + 0.1 * k)
        policy.add_frame(0, 10 + 0.1 * k, 'a', 100 + 0.1 * k)
        policy.add_frame(1, 10.05 + 0.1 * k, 'b', 100 + 0.1 * k)
        assert policy.poll(100 + 0.1 * k) is None
    assert log.count('no set of frames with stamps within') == 1
    assert log.count('cam0 -50 ms') == 1


@pytest.mark.parametrize('jump_s', [1000.0, -1000.0, -3.0])
def test_a_time_jump_resets_the_policy_and_stitching_goes_on(jump_s):
    """One set stamped in the future, or the clock going back: reset, counted, said."""
    policy, log = _policy()
    now, stamp = 100.0, 10.0
    published = []
    for k in range(60):
        if k == 20:
            stamp += jump_s            # the clock jumps (a bag loop) or one set is odd
        if k == 21 and jump_s > 0:
            stamp -= jump_s            # ... and only that one set was in the future
        _feed(policy, stamp, now)
        frame_set = policy.poll(now)
        if frame_set is not None:
            published.append(frame_set.stamp_s)
        now += 0.1
        stamp += 0.1
    assert len(published) >= 55 and published[-1] == pytest.approx(stamp - 0.1)
    assert policy.time_jumps == (2 if jump_s > 0 else 1)
    assert log.count('time jump of') == 1           # at most one line a second
    assert 'camera cam0' in policy.last_jump


def test_without_jump_detection_a_future_set_stops_everything():
    """The failure of issue 14 (regression guard): with the detection off, no more sets."""
    policy = FrameSetPolicy(['a', 'b'], SETTINGS, jump_threshold_s=math.inf)
    _feed(policy, 10.0, 100.0, cameras=(0, 1))
    assert policy.poll(100.0) is not None
    _feed(policy, 1e6, 100.1, cameras=(0, 1))
    policy.poll(100.1)
    _feed(policy, 10.2, 100.2, cameras=(0, 1))
    for k in range(30):
        _feed(policy, 10.3 + 0.1 * k, 100.3 + 0.1 * k, cameras=(0, 1))
        assert policy.poll(100.3 + 0.1 * k) is None
    assert policy.time_jumps == 0


def test_a_camera_back_after_a_long_pause_is_not_a_jump():
    """Stamps that advance with the wall time are no jump, however long the pause."""
    policy, log = _policy()
    _feed(policy, 10.0, 100.0)
    _feed(policy, 70.0, 160.0)
    assert policy.poll(160.0).stamp_s == 70.0 and policy.time_jumps == 0


def test_not_finite_attitude_and_rejected_frames_are_said_once():
    """Refuse NaN attitudes (said once) and count rejected frames per camera."""
    policy, log = _policy()
    assert not policy.add_attitude(0.0, math.nan, 0.0, 1.0)
    assert not policy.add_attitude(0.0, 0.0, math.inf, 1.0)
    assert log.count('attitude rejected') == 1
    policy.reject_frame(1, 'bad size')
    policy.reject_frame(1, 'bad size')
    assert log.count('frame rejected: bad size') == 1
    state = policy.cameras(2.0)[1]
    assert state.rejected == 2 and state.reject_reason == 'bad size' and state.age_s is None


def test_the_worker_thread_hands_sets_on_and_survives_errors():
    """The worker thread polls on wake(), calls stitch, passes exceptions to on_error."""
    policy, _ = _policy(n=1)
    got, errors = [], []
    failed, done = threading.Event(), threading.Event()

    def stitch(frame_set):
        got.append(frame_set.stamp_s)
        if len(got) == 1:
            raise ValueError('first fails')
        done.set()

    def on_error(exc):
        errors.append(exc)
        failed.set()

    clock = [100.0]
    worker = FrameSetWorker(policy, stitch, on_error, clock=lambda: clock[0])
    try:
        _feed(policy, 10.0, 100.0, cameras=(0,))
        worker.wake()
        assert failed.wait(30.0)
        clock[0] = 101.0
        _feed(policy, 11.0, 101.0, cameras=(0,))
        worker.wake()
        assert done.wait(30.0)
    finally:
        worker.close()
    assert got == [10.0, 11.0] and isinstance(errors[0], ValueError)


def test_a_dropped_frame_costs_one_set_only():
    """Camera 1 misses one frame (a lossy link): that set is skipped, the next one is whole."""
    policy, log = _policy()
    stamps = []
    for k in range(10):
        stamp, now = 10.0 + 0.1 * k, 100.0 + 0.1 * k
        _feed(policy, stamp, now, cameras=(0, 2) if k == 4 else (0, 1, 2))
        frame_set = policy.poll(now)
        if frame_set is not None:
            assert None not in frame_set.images
            stamps.append(round(frame_set.stamp_s, 3))
    assert stamps == [round(10.0 + 0.1 * k, 3) for k in range(10) if k != 4]
    assert policy.time_jumps == 0 and not any(state.stalled for state in policy.cameras(101.0))


def test_dropped_input_goes_to_on_drop_instead_of_the_log():
    """With on_drop every drop is handed on by kind (frames per camera name); no log."""
    drops = []
    log = []
    policy = FrameSetPolicy(['cam0 (a)', 'cam1 (b)'], SETTINGS,
                            lambda level, text: log.append(text),
                            on_drop=lambda kind, reason, detail='': drops.append(kind),
                            names=['cam0', 'cam1'])
    assert not policy.add_attitude(0.0, 0.0, 4.0, 1.0)
    policy.reject_frame(1, 'bad size')
    policy.reject_frame(1, 'bad size')
    assert drops == ['attitudes', 'cam1_frames', 'cam1_frames']
    assert not [t for t in log if 'rejected' in t]
    assert policy.rejected_attitudes == 1 and policy.cameras(2.0)[1].rejected == 2
