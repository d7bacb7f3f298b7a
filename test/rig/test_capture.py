"""Live pose capture (core of the rig_calibration node), fed rendered frames and gravity."""
from accelcal_ros.rig.capture import RigCapture
from accelcal_ros.rig.dataset import scan_directory
from accelcal_ros.rig.render import default_truth, imu_samples, plan_poses, Renderer
import numpy as np

TRUTH = default_truth()


def _feed(capture, renderer, pose, t0, rng, moving=False):
    samples = imu_samples(TRUTH, pose, rng, duration_s=1.5, motion_m_s2=2.0 if moving else 0)
    images = [renderer.render(pose, i) for i in range(len(TRUTH.names))]
    names = []
    for k, (t, a) in enumerate(zip(samples['t'], samples['a'])):
        if k % 10 == 0:
            for cam, image in zip(TRUTH.names, images):
                capture.add_image(cam, t0 + t, image)
        name = capture.add_imu(t0 + t, a)
        if name:
            names.append(name)
    return names


def test_still_poses_with_a_board_are_captured_once(tmp_path):
    """One pose per still period; a shaking period gives none; status counts views."""
    poses = plan_poses(TRUTH, 4)
    renderer = Renderer(TRUTH)
    rng = np.random.default_rng(0)
    capture = RigCapture(str(tmp_path), TRUTH.names, TRUTH.board, min_still_s=0.6)
    captured = []
    for k, pose in enumerate(poses):
        captured += _feed(capture, renderer, pose, 10.0 * k, rng, moving=(k == 2))
    assert captured == ['pose00', 'pose01', 'pose02']
    data = scan_directory(str(tmp_path))
    assert data.cameras == TRUTH.names and len(data.poses) == 3
    status = capture.status()
    expected = [sum(1 for k in (0, 1, 3) if i in poses[k].visible) for i in range(3)]
    assert [status['cameras'][c]['views'] for c in TRUTH.names] == expected
    assert status['shared_views']['cam0-cam1'] == sum(
        1 for k in (0, 1, 3) if {0, 1} <= set(poses[k].visible))
    assert 'show' in status['next']


def test_manual_capture_needs_a_still_rig(tmp_path):
    """The capture service refuses while moving, captures when still."""
    pose = plan_poses(TRUTH, 1)[0]
    renderer = Renderer(TRUTH)
    capture = RigCapture(str(tmp_path), TRUTH.names, TRUTH.board, auto=False)
    _feed(capture, renderer, pose, 0.0, np.random.default_rng(1), moving=True)
    ok, message = capture.capture()
    assert not ok and 'moving' in message
    _feed(capture, renderer, pose, 5.0, np.random.default_rng(2))
    ok, message = capture.capture()
    assert ok and 'pose00' in message and 'cam0' in message


def test_a_pose_after_the_clock_jumps_back_reads_back(tmp_path):
    """
    Samples from before a jump back (a bag played again) stay out of the next pose.

    Kept, they were written first into its imu.csv (times not increasing), and the whole
    calibration then failed to read that pose.
    """
    from accelcal_ros.sensor.recording import load_recording

    poses = plan_poses(TRUTH, 2)
    renderer = Renderer(TRUTH)
    rng = np.random.default_rng(3)
    capture = RigCapture(str(tmp_path), TRUTH.names, TRUTH.board, min_still_s=0.6)
    assert _feed(capture, renderer, poses[0], 100.0, rng) == ['pose00']
    capture.restart_clock()   # the node's answer to StampOrder's JUMPED_BACK
    assert _feed(capture, renderer, poses[1], 99.0, rng) == ['pose01']
    t, _ = load_recording(str(tmp_path / 'pose01' / 'imu.csv'))
    assert t[0] >= 99.0 and t[-1] < 100.6
    assert len(scan_directory(str(tmp_path)).poses) == 2
