"""Floor plane fit, Wahba solver and the boresight on paper B's simulated protocol."""
from accelcal_ros.errors import CalibrationError, GeometryError
from accelcal_ros.lidar import scanner_sim as sim
from accelcal_ros.lidar.boresight import calibrate_boresight, StaticPosition
from accelcal_ros.lidar.plane_fit import find_floor, find_planes, FloorSearch, msac_plane
from accelcal_ros.lidar.static_segments import find_static_segments, longest_static_segment
from accelcal_ros.lidar.wahba import (holdout, observability_warnings, pair_errors_deg,
                                      rotation_angle_deg, rotation_covariance, solve_wahba)
from accelcal_ros.sensor.model import SensorModel
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

TRUTH = sim.default_boresight()


@pytest.fixture(scope='module')
def protocol():
    """Paper B's 15 positions, simulated once for the module."""
    return sim.simulate_protocol(TRUTH, seed=2)


def _plane_points(normal, d, n=3000, noise=0.01, outliers=500, seed=0):
    rng = np.random.default_rng(seed)
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    u = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    uv = rng.uniform(-4, 4, (n, 2))
    pts = -d * normal + uv[:, :1] * u + uv[:, 1:] * v + rng.normal(0, noise, (n, 1)) * normal
    return np.vstack([pts, rng.uniform(-5, 5, (outliers, 3))])


@settings(max_examples=15, deadline=None)
@given(st.floats(-1, 1), st.floats(-1, 1), st.floats(0.3, 1), st.floats(0.5, 3))
def test_msac_recovers_plane_oriented_to_scanner(a, b, c, height):
    """MSAC + refit finds the plane within 0.2 deg; the normal points at the origin."""
    normal = np.array([a, b, c]) / np.linalg.norm([a, b, c])
    pts = _plane_points(normal, height)
    plane = msac_plane(pts, FloorSearch(min_inliers=100))
    assert plane is not None and plane.d > 0
    assert np.degrees(np.arccos(min(1.0, plane.normal @ normal))) < 0.2
    assert abs(plane.d - height) < 0.01


def test_gravity_guided_search_prefers_floor_over_a_larger_wall():
    """With the up prior, a bigger wall is ignored and the floor is found."""
    floor = _plane_points([0, 0, 1], 1.0, n=1500, outliers=0)
    wall = _plane_points([1, 0, 0], 2.0, n=6000, outliers=0, seed=1)
    pts = np.vstack([floor, wall, np.full((5, 3), np.nan)])
    search = FloorSearch(max_height_m=10.0)
    assert abs(msac_plane(pts, search).normal[0]) > 0.99   # unguided: the wall
    plane = find_floor(pts, search, up=[0.05, 0, 1])
    assert plane.normal[2] > 0.999 and len(plane.inliers) > 1400
    with pytest.raises(GeometryError, match='no plane within'):
        find_floor(wall, search, up=[0, 0, 1])
    planes = find_planes(pts, search)
    assert len(planes) >= 2


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000))
def test_wahba_exact_and_matches_scipy(seed):
    """Noiseless pairs give the rotation back; same as scipy align_vectors."""
    rng = np.random.default_rng(seed)
    truth = Rotation.random(random_state=seed).as_matrix()
    n = rng.normal(size=(6, 3))
    f = n @ truth.T
    r = solve_wahba(n, f)
    assert rotation_angle_deg(r, truth) < 1e-6
    w = rng.uniform(0.5, 2, 6)
    noisy = f + rng.normal(0, 0.01, f.shape)
    un = n / np.linalg.norm(n, axis=1, keepdims=True)
    uf = noisy / np.linalg.norm(noisy, axis=1, keepdims=True)
    ref = Rotation.align_vectors(uf, un, weights=w)[0].as_matrix()
    assert rotation_angle_deg(solve_wahba(n, noisy, w), ref) < 1e-6


def test_covariance_matches_monte_carlo():
    """The predicted rotation covariance matches the scatter of noisy solutions."""
    rng = np.random.default_rng(0)
    f = rng.normal(size=(15, 3))
    f /= np.linalg.norm(f, axis=1, keepdims=True)
    sigma = np.radians(0.1)
    angles, predicted = [], []
    for _ in range(300):
        noisy = f + rng.normal(0, sigma / np.sqrt(2), f.shape)
        r = solve_wahba(f, noisy)
        angles.append(Rotation.from_matrix(r).as_rotvec())
        predicted.append(np.trace(rotation_covariance(r, f, noisy)[0]))
    empirical = np.sum(np.var(angles, axis=0))
    assert 0.7 < np.mean(predicted) / empirical < 1.4


def test_observability_warning():
    """Nearly parallel gravity directions warn; the paper's protocol does not."""
    f = np.array([[0.0, 0.01, 1], [0.02, 0, 1], [0, -0.02, 1]])
    assert 'do not constrain' in observability_warnings(f)[0]
    tilts = sim.paper_protocol_tilts_deg()
    ups = [(sim.rot_x(np.radians(a)) @ sim.rot_y(np.radians(b))).T @ [0, 0, 1] for a, b in tilts]
    assert observability_warnings(ups) == []


def test_static_segments_from_gyro_and_accelerometer():
    """The handling motion is excluded; accel-only logs work; a calibration is applied."""
    rng = np.random.default_rng(0)
    model = SensorModel([1.01, 0.99, 1.02], [0.02, -0.01, 0.03], [0, 0, 0])
    log, f_true = sim.simulate_imu_static(np.eye(3), 5.0, 200.0, rng, model)
    seg = longest_static_segment(log.t, log.accel, log.gyro, model)
    assert seg.t_start >= 1.0 and seg.duration_s > 4.0
    assert np.linalg.norm(seg.gravity_m_s2 - f_true) < 0.01
    raw = longest_static_segment(log.t, log.accel, None)
    assert raw.t_start >= 1.0
    assert np.linalg.norm(raw.gravity_m_s2 - f_true) > 0.1  # bias not removed
    assert find_static_segments(log.t[:150], log.accel[:150], log.gyro[:150]) == []


@pytest.mark.parametrize('use_prior', [True, False])
def test_protocol_boresight_under_005_deg(protocol, use_prior):
    """Paper B's 15 positions recover the boresight to better than 0.05 deg."""
    positions = sim.positions_for_calibration(protocol)
    res = calibrate_boresight(positions, sim.nominal_mount() if use_prior else None)
    assert rotation_angle_deg(res.rotation, TRUTH) < 0.05
    assert len(res.positions) == 15 and not res.dropped
    # without a prior the room's half turns fit too; the floor height rules them out (noted)
    assert all('ruled out' in w for w in res.warnings) and bool(res.warnings) != use_prior
    assert res.mean_error_deg < 0.1 and res.holdout['mean'] < 0.15
    assert res.holdout['even_vs_odd_rotation'] < 0.1
    assert np.all(res.rpy_std_deg < 0.05)
    np.testing.assert_allclose(res.per_position_error_deg,
                               pair_errors_deg(res.rotation, res.normals, res.gravity))


def test_bad_positions_are_dropped_with_reasons(protocol):
    """An empty and a floorless cloud are dropped; NaN points are ignored; rest go on."""
    positions = sim.positions_for_calibration(protocol)
    positions[0] = StaticPosition('pos01', np.zeros((0, 3)), positions[0].gravity_m_s2)
    pts = positions[1].points
    positions[1] = StaticPosition('pos02', pts[pts @ (sim.nominal_mount().T
                                                      @ positions[1].gravity_m_s2) > 0],
                                  positions[1].gravity_m_s2)
    nan_pts = positions[2].points.copy()
    nan_pts[::7] = np.nan
    positions[2] = StaticPosition('pos03', nan_pts, positions[2].gravity_m_s2)
    for prior in (sim.nominal_mount(), None):
        res = calibrate_boresight(positions, prior)
        assert set(res.dropped) == {'pos01', 'pos02'}
        assert 'empty' in res.dropped['pos01']
        assert rotation_angle_deg(res.rotation, TRUTH) < 0.06
    with pytest.raises(CalibrationError, match='usable position'):
        calibrate_boresight(positions[:2], sim.nominal_mount())


def test_uncalibrated_accelerometer_bias_shows(protocol):
    """A biased IMU without its calibration gives a visibly worse boresight."""
    model = SensorModel([1.0, 1.0, 1.0], [0.01, -0.012, 0.008], [0, 0, 0])
    biased = sim.simulate_protocol(TRUTH, seed=4, imu_model=model)
    bad = calibrate_boresight(sim.positions_for_calibration(biased), sim.nominal_mount())
    good = calibrate_boresight(sim.positions_for_calibration(biased, model), sim.nominal_mount())
    assert rotation_angle_deg(good.rotation, TRUTH) < 0.05
    assert rotation_angle_deg(bad.rotation, TRUTH) > 0.1


def test_holdout_structure():
    """The hold-out reports every position under the fit that excluded it."""
    f = np.random.default_rng(1).normal(size=(6, 3))
    res = holdout(f, f)
    assert len(res['per_position']) == 6 and res['mean'] < 1e-6
