"""Georeferencing against the moving-platform truth, error budget, streaming cores."""
from accelcal_ros.errors import InputError
from accelcal_ros.lidar import scanner_sim as sim
from accelcal_ros.lidar.assembler import CloudAssembler, RunningClock
from accelcal_ros.lidar.capture import CaptureSettings, StaticCapture
from accelcal_ros.lidar.cloud import make_cloud, point_times, xyz
from accelcal_ros.lidar.error_budget import error_budget, paper_totals_m, sync_error_m
from accelcal_ros.lidar.georef import georeference
from accelcal_ros.lidar.poses import PoseStream
import numpy as np
import pytest
from scipy.interpolate import interp1d
from scipy.spatial.transform import Rotation, Slerp


@pytest.fixture(scope='module')
def scene():
    """Simulate a noiseless 0.3 s moving-platform scan with its truth."""
    return sim.simulate_moving_platform(0.3, range_noise_m=0.0)


def test_georeference_matches_known_geometry(scene):
    """Noiseless points land on the true hit points to well under a millimetre."""
    times = point_times(scene.cloud, scene.scan_start_s)
    pts, keep, stats = georeference(xyz(scene.cloud), times, scene.poses, scene.boresight,
                                    scene.lever_arm_m)
    assert stats.kept == len(scene.cloud) and keep.all()
    err = np.linalg.norm(pts - scene.truth_world, axis=1)
    assert err.max() < 1e-3
    wrong = georeference(xyz(scene.cloud), times, scene.poses, np.eye(3), scene.lever_arm_m)[0]
    assert np.median(np.linalg.norm(wrong - scene.truth_world, axis=1)) > 0.5


def test_georeference_equals_scipy_slerp():
    """The vectorised slerp equals scipy's Slerp and linear position interpolation."""
    rng = np.random.default_rng(0)
    tk = np.linspace(0, 2, 41)
    rot = Rotation.random(41, random_state=1)
    poses = PoseStream(tk, rng.normal(size=(41, 3)), rot.as_quat())
    t = rng.uniform(0, 2, 20000)
    p = rng.normal(size=(20000, 3)) * 10
    b = Rotation.from_euler('xyz', [3, -2, 40], degrees=True).as_matrix()
    lever = np.array([0.2, -0.1, 0.3])
    ours, _, _ = georeference(p, t, poses, b, lever, threads=2, chunk=4096)
    ref = Slerp(tk, rot)(t).apply(p @ b.T + lever) + interp1d(tk, poses.position, axis=0)(t)
    assert np.abs(ours - ref).max() < 1e-9


def test_points_outside_the_pose_span_are_dropped_and_counted():
    """A pose stream shorter than the scan: points before/after are counted, NaN too."""
    short = sim.simulate_moving_platform(0.2, range_noise_m=0.0, pose_margin_s=-0.05)
    times = point_times(short.cloud, short.scan_start_s)
    pts = xyz(short.cloud)
    pts[:10] = np.nan
    out, keep, stats = georeference(pts, times, short.poses, short.boresight,
                                    short.lever_arm_m)
    t0, t1 = short.poses.span
    assert stats.before_span == int(np.sum(times[10:] < t0)) > 0
    assert stats.after_span == int(np.sum(times > t1)) > 0
    assert stats.non_finite == 10 and len(out) == stats.kept == keep.sum()
    assert np.linalg.norm(out - short.truth_world[keep], axis=1).max() < 1e-3


def test_error_budget_reproduces_paper():
    """Eq. (1) with the paper's printed terms gives 1.76 m and 0.56 m."""
    before, after = paper_totals_m()
    assert round(before, 2) == 1.76 and round(after, 2) == 0.56
    exact = error_budget(boresight_deg=1.0)
    assert abs(exact['total'] - 1.76) < 0.01 and abs(error_budget()['total'] - 0.56) < 0.01
    assert sync_error_m(10e-6, 30 / 3.6, 180.0, 100.0) < 0.005


def test_static_capture_pairs_rest_with_scans():
    """Auto capture once per still period, with the mean gravity; motion re-arms it."""
    cap = StaticCapture(CaptureSettings(min_static_s=0.5))
    rng = np.random.default_rng(0)
    scan = np.array([[1.0, 0.0, -1.0]] * 10)
    captured = []
    for k in range(1200):
        t = k * 0.01
        moving = 3.0 < t < 4.0
        gyro = rng.normal(0, 0.3 if moving else 0.001, 3)
        g = [0, 0, 9.8] if t < 3.5 else [0, 9.8, 0]
        cap.add_imu(t, np.asarray(g) + rng.normal(0, 0.01, 3), gyro)
        if k % 10 == 0:
            cap.add_cloud(t, scan)
        captured += cap.positions[len(captured):]   # captures happen as the IMU catches up
    assert len(captured) == 2
    assert np.allclose(captured[0].gravity_m_s2, [0, 0, 9.8], atol=0.01)
    assert np.allclose(captured[1].gravity_m_s2, [0, 9.8, 0], atol=0.01)
    assert cap.capture_now()[0] is None
    late = StaticCapture(CaptureSettings(min_static_s=0.5))
    for k in range(100):
        late.add_imu(k * 0.01, [0, 0, 9.8], [0, 0, 0])
    assert late.add_cloud(1.5, scan) is None        # newer than the IMU: waits
    for k in range(100, 160):
        late.add_imu(k * 0.01, [0, 9.8, 0], rng.normal(0, 0.3, 3))  # moved before 1.5 s
    assert late.positions == [] and not late.still


def test_static_capture_across_a_gap_in_the_imu_stream():
    """A gap ends the still period; same gravity after it is not captured twice."""
    cap = StaticCapture(CaptureSettings(min_static_s=0.5))
    scan = np.ones((5, 3))

    def feed(t0, t1, g):
        for t in np.arange(t0, t1, 0.01):
            cap.add_imu(t, g, [0.0, 0.0, 0.0])
        return cap.add_cloud(t1 - 0.02, scan)

    assert feed(0.0, 1.0, [0, 0, 9.8]) is not None
    assert feed(1.5, 2.5, [0, 0, 9.8]) is None          # gap, same position
    assert feed(3.0, 4.0, [0, 9.8, 0]) is not None       # gap, the rig moved unseen
    assert len(cap.positions) == 2


def test_assembler_waits_for_poses_and_rejects_out_of_order(scene):
    """Scans wait for odometry; out-of-order poses are rejected; no time -> error."""
    asm = CloudAssembler(scene.boresight, scene.lever_arm_m, max_wait_s=10.0)
    asm.add_scan(scene.scan_start_s, scene.cloud, now_s=0.0)
    poses = scene.poses
    half = len(poses.t) // 2
    for k in range(half):
        asm.add_pose(poses.t[k], poses.position[k], poses.quat_xyzw[k])
    assert asm.process(now_s=1.0) == []
    assert asm.add_pose(poses.t[0], poses.position[0], poses.quat_xyzw[0]) is not None
    for k in range(half, len(poses.t)):
        asm.add_pose(poses.t[k], poses.position[k], poses.quat_xyzw[k])
    (nav, stats), = asm.process(now_s=1.0)
    assert stats.kept == len(scene.cloud) and asm.rejected_poses == 1
    assert np.linalg.norm(xyz(nav) - scene.truth_world, axis=1).max() < 1e-3
    assert len(asm.map_cloud()) == len(scene.cloud)
    with pytest.raises(InputError, match='per-point time'):
        asm.add_scan(0.0, make_cloud(np.zeros((5, 3))), 0.0)


def test_assembler_waits_while_late_odometry_still_arrives_and_not_for_a_stopped_stream(scene):
    """
    A scan waits while poses keep arriving, however late; a stopped stream ends the wait.

    On a busy machine the odometry can reach the node more than ``max_wait_s`` after the
    scans it covers (the demo beside two CPU hogs lost 4.5 % of its points so): the wait
    now counts from the newest pose's arrival. Previous code: the scan below was processed
    at 0.6 s with half of its points dropped as "after the poses".
    """
    poses, n = scene.poses, len(scene.poses.t)
    asm = CloudAssembler(scene.boresight, scene.lever_arm_m, max_wait_s=0.5)
    asm.add_scan(scene.scan_start_s, scene.cloud, now_s=0.0)
    last_point = scene.scan_start_s + float(scene.cloud['time'].max())
    now, done = 0.0, []
    for chunk in np.array_split(np.arange(n), 8):   # poses every 0.3 s of the node's clock
        now += 0.3
        for k in chunk:
            asm.add_pose(poses.t[k], poses.position[k], poses.quat_xyzw[k], now_s=now)
        done = asm.process(now_s=now + 0.29)
        assert bool(done) == (poses.t[k] >= last_point), f'at {now:.1f} s'
        if done:
            break
    (nav, stats), = done
    assert now > 1.5 and stats.kept == len(scene.cloud) and stats.after_span == 0
    # a stream that stops half way: the scan goes after max_wait_s with what is there
    asm = CloudAssembler(scene.boresight, scene.lever_arm_m, max_wait_s=0.5)
    asm.add_scan(scene.scan_start_s, scene.cloud, now_s=0.0)
    for k in range(n // 2):
        asm.add_pose(poses.t[k], poses.position[k], poses.quat_xyzw[k], now_s=1.0)
    assert asm.process(now_s=1.49) == []
    (nav, stats), = asm.process(now_s=1.51)
    assert 0 < stats.kept < len(scene.cloud) and stats.after_span > 0
    assert stats.kept + stats.after_span + stats.before_span == len(scene.cloud)


def test_a_cpu_stall_does_not_end_a_scans_wait_on_the_running_clock(scene):
    """
    The node starved of CPU for 2 s: on its running clock the scan still waits for the poses.

    The node's 20 ms timer ticks the clock; a stall (no callback ran, the odometry queued)
    counts as one step of ``RUNNING_STEP_S``. On the wall clock (previous code) the first
    tick after the stall found the scan 2 s old and no pose for 2 s, and sent it with the
    poses there were: half its points "after the poses" (CI, the drive's last scans).
    """
    poses, n = scene.poses, len(scene.poses.t)
    for clock in (RunningClock(), None):   # the node's clock; the wall clock before
        asm = CloudAssembler(scene.boresight, scene.lever_arm_m, max_wait_s=0.5)
        wall = 100.0
        now = clock.tick(wall) if clock else wall
        for k in range(n // 2):
            asm.add_pose(poses.t[k], poses.position[k], poses.quat_xyzw[k], now_s=now)
        asm.add_scan(scene.scan_start_s, scene.cloud, now_s=now)
        for _ in range(5):  # 20 ms ticks, then the stall
            wall += 0.02
            assert asm.process(clock.tick(wall) if clock else wall) == []
        wall += 2.0
        now = clock.tick(wall) if clock else wall
        done = asm.process(now)  # the timer first, the odometry callbacks after it
        if clock is None:
            (_, stats), = done
            assert stats.after_span > 0
            continue
        assert done == [] and clock.stalled_s == pytest.approx(1.9)
        for k in range(n // 2, n):
            asm.add_pose(poses.t[k], poses.position[k], poses.quat_xyzw[k], now_s=now)
        (_, stats), = asm.process(clock.tick(wall + 0.02))
        assert stats.kept == len(scene.cloud) and stats.after_span == 0
    # a stream that stopped: the wait still ends after max_wait_s of steady ticks
    clock = RunningClock()
    asm = CloudAssembler(scene.boresight, scene.lever_arm_m, max_wait_s=0.5)
    asm.add_pose(poses.t[0], poses.position[0], poses.quat_xyzw[0], now_s=clock.tick(0.0))
    asm.add_pose(poses.t[1], poses.position[1], poses.quat_xyzw[1], now_s=clock.tick(0.0))
    asm.add_scan(scene.scan_start_s, scene.cloud, now_s=clock.tick(0.0))
    ticks = 0
    while not asm.process(clock.tick(0.02 * (ticks + 1))):
        ticks += 1
    assert ticks + 1 == pytest.approx(25, abs=1) and clock.stalled_s == 0.0


def test_assembler_bounds_the_scans_waiting_for_poses(scene):
    """More waiting points than ``max_pending_points``: the oldest scan goes first."""
    poses = scene.poses
    asm = CloudAssembler(scene.boresight, scene.lever_arm_m, max_wait_s=10.0,
                         max_pending_points=len(scene.cloud))
    for k in range(len(poses.t) // 2):
        asm.add_pose(poses.t[k], poses.position[k], poses.quat_xyzw[k], now_s=0.0)
    asm.add_scan(scene.scan_start_s, scene.cloud, now_s=0.0)
    assert asm.process(now_s=0.1) == []
    asm.add_scan(scene.scan_start_s, scene.cloud, now_s=0.1)   # twice the cap waits
    (nav, stats), = asm.process(now_s=0.2)
    assert stats.after_span > 0 and len(asm._pending) == 1


def test_assembler_drops_points_in_a_pose_gap_instead_of_interpolating_across_it():
    """
    Lost odometry: points between poses further apart than ``max_gap_s`` are dropped.

    One fresh-clone demo run on a stalled machine most likely lost a stretch of odometry
    and interpolated across it: 35 cm rms in one scan, 11 cm over the run, nothing counted.
    Here a straight line across 0.35 s of the platform's motion is 6.4 cm rms, 18 cm at
    worst off.
    """
    scene = sim.simulate_moving_platform(2.0, range_noise_m=0.0, seed=1)
    poses = scene.poses
    n = len(poses.t)
    gap = (np.arange(n) > n // 3) & (np.arange(n) < n // 2)   # 0.35 s of odometry lost
    results = {}
    for limit in (None, 0.25):
        asm = CloudAssembler(scene.boresight, scene.lever_arm_m, max_gap_s=limit)
        for k in np.flatnonzero(~gap):
            asm.add_pose(poses.t[k], poses.position[k], poses.quat_xyzw[k], now_s=0.0)
        asm.add_scan(scene.scan_start_s, scene.cloud, now_s=0.0)
        (nav, stats), = asm.process(now_s=0.0)
        times = point_times(scene.cloud, scene.scan_start_s, None)
        inside = (times > poses.t[n // 3]) & (times < poses.t[n // 2])
        kept = np.ones(len(scene.cloud), bool) if limit is None else ~inside
        error = np.linalg.norm(xyz(nav) - scene.truth_world[kept], axis=1)
        results[limit] = (stats, error, asm)
    stats, error, _ = results[None]
    assert stats.in_gap == 0 and error.max() > 0.1   # interpolated across: wrong
    stats, error, asm = results[0.25]
    assert stats.in_gap == int(inside.sum()) > 0 and error.max() < 1e-3
    assert asm.totals['in_gap'] == stats.in_gap and 'in pose gaps' in asm.summary()


def test_error_budget_refuses_angles_without_a_lateral_error(capsys):
    """--attitude-deg 120 printed an attitude term of -173.205 m; 90 deg is unbounded."""
    from accelcal_ros.cli import main
    from accelcal_ros.errors import InputError
    from accelcal_ros.lidar.error_budget import angle_to_metres

    for angle in (90.0, 120.0, 179.0, -1.0):
        with pytest.raises(InputError, match='outside 0 to 90 deg'):
            angle_to_metres(angle, 100.0)
    assert angle_to_metres(89.0, 100.0) == pytest.approx(100.0 * np.tan(np.radians(89.0)))
    for option in ('--attitude-deg', '--boresight-deg'):
        for value in ('90', '120'):
            assert main(['error-budget', option, value]) == 2
            err = capsys.readouterr().err
            assert err.count('\n') == 1 and option in err and 'must be < 90' in err
    assert main(['error-budget', '--attitude-deg', '45']) == 0
    assert 'attitude 100.000 m' in capsys.readouterr().out   # 100 m x tan 45 deg
