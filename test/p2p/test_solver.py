"""P2P solver with known vertical: exactness, yaw contract, degenerate input, batch form."""
import warnings

from accelcal_ros.errors import GeometryError, InputError
from accelcal_ros.frames import (DEFAULT_IMU_TO_CAMERA, down_in_camera,
                                 rotation_from_rpy_radians, rpy_radians_from_rotation)
from accelcal_ros.p2p import solver
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest


def make_problem(rng, yaw=None, vertical_spread=True):
    """Return ``(R, t, points, rays, down)`` of a random well-conditioned problem."""
    yaw = rng.uniform(-np.pi, np.pi) if yaw is None else yaw
    roll, pitch = rng.uniform(-0.8, 0.8), rng.uniform(-1.2, 1.2)
    body = rotation_from_rpy_radians(roll, pitch, yaw)
    rotation = DEFAULT_IMU_TO_CAMERA @ body.T
    while True:
        cam_points = np.column_stack([rng.uniform(-1.0, 1.0, 2), rng.uniform(-1.0, 1.0, 2),
                                      rng.uniform(1.5, 6.0, 2)])
        translation = rng.normal(size=3) * 3.0
        points = (cam_points - translation) @ rotation      # R^T (X_cam - t)
        delta = points[0] - points[1]
        level_rays = (cam_points / np.linalg.norm(cam_points, axis=1)[:, None]) @ rotation
        if not vertical_spread:
            points[1, 2] = points[0, 2]
            cam_points = points @ rotation.T + translation
            if np.any(cam_points[:, 2] < 0.5):
                continue
            level_rays = (cam_points / np.linalg.norm(cam_points, axis=1)[:, None]) @ rotation
            delta = points[0] - points[1]
        if (np.hypot(delta[0], delta[1]) > 0.2 * np.linalg.norm(delta)
                and np.abs(level_rays[:, 2]).max() > 0.1
                and np.linalg.norm(np.cross(*level_rays)) > 0.05):
            break
    down = rotation @ np.array([0.0, 0.0, -1.0])
    return rotation, translation, points, cam_points, down


def best_error(solutions, rotation, translation):
    """Return the smallest (rotation max-abs error, relative translation error)."""
    errors = [(np.abs(s.rotation - rotation).max(),
               np.linalg.norm(s.translation - translation) / np.linalg.norm(translation))
              for s in solutions]
    return min(errors, key=sum)


def test_noise_free_random_problems_exact_to_1e9():
    rng = np.random.default_rng(7)
    for k in range(400):
        yaw = None
        if k % 4 == 0:   # yaw at and near +-180 deg: where tan(yaw/2) breaks down
            yaw = np.pi * rng.choice([-1.0, 1.0]) - rng.choice([0.0, 1e-12, 1e-6, 1e-3])
        rotation, translation, points, rays, down = make_problem(rng, yaw,
                                                                 vertical_spread=k % 2 == 0)
        solutions = solver.solve(rays, points, down)
        assert 1 <= len(solutions) <= 2
        rot_err, trans_err = best_error(solutions, rotation, translation)
        assert rot_err < 1e-9 and trans_err < 1e-9, (k, rot_err, trans_err)
        for s in solutions:     # every returned solution is a valid pose
            assert np.allclose(s.rotation @ s.rotation.T, np.eye(3), atol=1e-12)
            assert np.linalg.det(s.rotation) == pytest.approx(1.0)
            assert np.allclose(s.rotation @ [0, 0, -1.0], down, atol=1e-12)
            cam = points @ s.rotation.T + s.translation
            assert np.all(cam[:, 2] > 0)
            assert np.all(np.linalg.norm(np.cross(cam, rays), axis=1)
                          < 1e-9 * np.linalg.norm(cam, axis=1) * np.linalg.norm(rays, axis=1))


def test_exactly_180_degrees_yaw():
    rotation = DEFAULT_IMU_TO_CAMERA @ rotation_from_rpy_radians(0.0, 0.3, np.pi).T
    centre = np.array([4.0, 0.3, 2.0])
    translation = -rotation @ centre
    points = np.array([[0.0, -0.5, 0.0], [0.0, 0.5, 0.0]])
    rays = points @ rotation.T + translation
    [s] = solver.solve(rays, points, rotation @ [0, 0, -1.0])
    assert abs(abs(s.yaw) - np.pi) < 1e-12
    assert np.allclose(s.camera_position, centre, atol=1e-12)
    assert s.range_m == pytest.approx(np.linalg.norm(translation))


@settings(max_examples=150, deadline=None)
@given(yaw=st.floats(-np.pi, np.pi), roll=st.floats(-1.0, 1.0), pitch=st.floats(-1.3, 1.3),
       height=st.floats(0.3, 5.0), side=st.floats(-2.0, 2.0), depth=st.floats(2.0, 20.0),
       baseline=st.floats(0.2, 3.0), heading=st.floats(-np.pi, np.pi),
       rise=st.floats(-1.0, 1.0), above=st.booleans())
def test_property_truth_is_among_the_solutions(yaw, roll, pitch, height, side, depth,
                                               baseline, heading, rise, above):
    """A camera above/below a pair of emitters seen in front: the truth is recovered."""
    body = rotation_from_rpy_radians(roll, pitch, yaw)
    rotation = DEFAULT_IMU_TO_CAMERA @ body.T
    forward = body[:, 0]
    centre = np.zeros(3)
    mid = centre + depth * forward + side * body[:, 1]
    mid[2] += (height if above else -height)
    direction = np.array([np.cos(heading), np.sin(heading), rise])
    points = mid + 0.5 * baseline * np.stack([-direction, direction])
    translation = -rotation @ centre
    cam = points @ rotation.T + translation
    rays = cam / np.linalg.norm(cam, axis=1)[:, None]
    level = rays @ rotation
    if (np.any(cam[:, 2] < 0.2) or np.linalg.norm(np.cross(*rays)) < 0.02
            or np.abs(level[:, 2]).max() < 0.05):
        return  # outside the well-conditioned family this property is about
    solutions = solver.solve(rays, points, rotation @ [0, 0, -1.0])
    best = min(solutions, key=lambda s: np.abs(s.rotation - rotation).max())
    scale = np.linalg.norm(cam, axis=1).max()   # the camera centre is the object origin here
    assert np.abs(best.rotation - rotation).max() < 1e-7
    assert np.abs(best.translation - translation).max() < 1e-7 * scale


def test_yaw_is_heading_of_optical_axis_and_rep103_yaw():
    rng = np.random.default_rng(3)
    for _ in range(200):
        roll, pitch, yaw = rng.uniform(-3, 3), rng.uniform(-1.5, 1.5), rng.uniform(-3.1, 3.1)
        body = rotation_from_rpy_radians(roll, pitch, yaw)
        rotation = DEFAULT_IMU_TO_CAMERA @ body.T
        expected = rpy_radians_from_rotation(body)[2]
        got = solver.yaw_from_rotation(rotation)
        assert abs(np.angle(np.exp(1j * (got - expected)))) < 1e-9
        axis = rotation.T @ [0, 0, 1.0]
        assert got == pytest.approx(np.arctan2(axis[1], axis[0]), abs=1e-12)
    # Camera along object +y, level: yaw = +90 deg (counter-clockwise from +x, seen from above).
    rotation = DEFAULT_IMU_TO_CAMERA @ rotation_from_rpy_radians(0, 0, np.pi / 2).T
    assert solver.yaw_from_rotation(rotation) == pytest.approx(np.pi / 2)


@pytest.mark.parametrize('pitch', [np.pi / 2, -np.pi / 2])
def test_yaw_continuous_at_vertical_optical_axis(pitch):
    for yaw in (-2.5, 0.0, 1.0, 3.0):
        exact = DEFAULT_IMU_TO_CAMERA @ rotation_from_rpy_radians(0.0, pitch, yaw).T
        near = DEFAULT_IMU_TO_CAMERA @ rotation_from_rpy_radians(
            0.0, pitch - np.sign(pitch) * 1e-6, yaw).T
        assert solver.yaw_from_rotation(exact) == pytest.approx(yaw, abs=1e-6)
        assert solver.yaw_from_rotation(near) == pytest.approx(yaw, abs=1e-6)


def test_vectorised_yaw_matches_scalar():
    rng = np.random.default_rng(5)
    rots = np.stack([DEFAULT_IMU_TO_CAMERA @ rotation_from_rpy_radians(*rng.uniform(-1, 1, 3)).T
                     for _ in range(10)])
    batch = solver.yaw_from_rotation(rots)
    assert batch.shape == (10,)
    assert np.allclose(batch, [solver.yaw_from_rotation(r) for r in rots])


def test_level_basis_is_a_rotation_for_every_direction():
    rng = np.random.default_rng(11)
    ups = rng.normal(size=(500, 3))
    ups = np.concatenate([ups, [[0, 0, 1.0], [0, 0, -1.0], [1e-300, 0, -1.0], [0, 1.0, 0]]])
    ups /= np.linalg.norm(ups, axis=1)[:, None]
    basis = solver.level_basis(ups)
    assert np.allclose(np.einsum('nji,njk->nik', basis, basis), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(basis), 1.0)
    assert np.allclose(basis[:, :, 2], ups)


def test_down_from_roll_pitch_matches_frames():
    rng = np.random.default_rng(2)
    roll, pitch = rng.uniform(-1, 1, 20), rng.uniform(-1, 1, 20)
    batch = solver.down_from_roll_pitch(roll, pitch)
    for k in range(20):
        assert np.allclose(batch[k], down_in_camera(roll[k], pitch[k]))
    # Level camera looking along body +x: down is +y of the optical frame.
    assert np.allclose(solver.down_from_roll_pitch(0.0, 0.0), [0, 1.0, 0])


def test_batch_equals_single_and_reports_per_problem():
    rng = np.random.default_rng(9)
    problems = [make_problem(rng) for _ in range(50)]
    rays = np.stack([p[3] for p in problems])
    points = np.stack([p[2] for p in problems])
    down = np.stack([p[4] for p in problems])
    rays[3] = np.nan                              # one bad problem does not spoil the rest
    points[4, 1] = points[4, 0] + [0, 0, 1.0]     # emitters on one vertical line
    result = solver.solve_batch(rays, points, down)
    assert len(result) == 50
    assert result.status[3] == solver.NOT_FINITE and not result.valid[3].any()
    assert result.status[4] == solver.VERTICAL_LINE
    assert 'vertical line' in result.reason(4)
    for k in set(range(50)) - {3, 4}:
        single = solver.solve(rays[k], points[k], down[k])
        batch = result.solutions(k)
        assert len(single) == len(batch) == result.valid[k].sum()
        for a, b in zip(single, batch):
            assert np.allclose(a.rotation, b.rotation, atol=1e-14)
            assert np.allclose(a.translation, b.translation, atol=1e-12)
        rot_err, trans_err = best_error(batch, problems[k][0], problems[k][1])
        assert rot_err < 1e-9 and trans_err < 1e-9
    assert np.isnan(result.rotations[~result.valid]).all()


def test_two_valid_solutions_are_both_consistent():
    rng = np.random.default_rng(21)
    found = 0
    for _ in range(3000):
        rotation, translation, points, rays, down = make_problem(rng)
        solutions = solver.solve(rays, points, down)
        if len(solutions) == 2:
            found += 1
            for s in solutions:
                cam = points @ s.rotation.T + s.translation
                assert np.all(cam[:, 2] > 0)
                assert np.linalg.norm(np.cross(cam, rays), axis=1).max() < 1e-9 * 10
            assert not np.allclose(solutions[0].translation, solutions[1].translation)
    assert found > 10


@pytest.mark.parametrize('points, rays, down, fragment', [
    ([[0, 0, 0], [0, 0, 0]], [[0, 0, 1], [0.1, 0, 1]], [0, 1, 0], 'coincide'),
    ([[1, 2, 0], [1, 2, 1]], [[0, 0, 1], [0, -0.2, 1]], [0, 1, 0], 'vertical line'),
    ([[0, 0, 0], [1, 0, 0]], [[0.1, 0.1, 1], [0.2, 0.2, 2]], [0, 1, 0], 'one camera ray'),
    ([[0, 0, 0], [1, 0, 0]], [[-0.1, 0, 1], [0.1, 0, 1]], [0, 1, 0], 'height'),
    ([[0, 0, 0], [1, 0, 0.5]], [[-0.1, 0, 1], [0.1, 0, 1]], [0, 1, 0], 'differ in height'),
    ([[0, 0, 0], [1, 0, 0]], [[-0.1, 0.1, 1], [0.1, 0.1, 1]], [0, 0, 0], 'zero length'),
    ([[0, 0, 0], [1, 0, 0]], [[-0.1, 0.1, -1], [0.1, 0.1, 1]], [0, 1, 0], 'backwards'),
])
def test_degenerate_input_raises_geometry_error(points, rays, down, fragment):
    with pytest.raises(GeometryError, match=fragment):
        solver.solve(rays, points, down)


def test_emitters_behind_the_camera_give_no_solution():
    # Level camera; two emitters at one height, one seen above and one below the horizon:
    # only a pose with one emitter behind the camera fits.
    points = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    rays = np.array([[0.0, -0.2, 1.0], [0.3, 0.2, 1.0]])
    with pytest.raises(GeometryError, match='in front of the camera'):
        solver.solve(rays, points, [0, 1.0, 0])
    result = solver.solve_batch(rays[None], points, [0, 1.0, 0])
    assert result.status[0] == solver.BEHIND_CAMERA


def test_inconsistent_vertical_gives_no_real_solution():
    # Emitters 5 m apart in height but 0.1 m horizontally, seen 33 deg apart at one
    # elevation: no distances fit (the line misses the ellipse).
    points = np.array([[0, 0, 0], [0.1, 0, 5.0]])
    rays = np.array([[-0.3, 0.1, 1.0], [0.3, 0.1, 1.0]])
    with pytest.raises(GeometryError, match='no real solution'):
        solver.solve(rays, points, [0, 1.0, 0])


@pytest.mark.parametrize('bad', ['rays', 'points', 'down'])
def test_nan_input_raises_input_error(bad):
    args = {'rays': np.array([[0, 0.1, 1], [0.2, 0.1, 1.0]]),
            'points': np.array([[0, 0, 0], [1.0, 0, 0]]), 'down': np.array([0, 1.0, 0])}
    args[bad] = args[bad].copy()
    args[bad].flat[0] = np.nan
    with pytest.raises(InputError, match='NaN'):
        solver.solve(**args)


def test_wrong_shapes_raise_input_error():
    with pytest.raises(InputError, match='shape'):
        solver.solve(np.zeros((3, 3)), np.zeros((2, 3)), [0, 1, 0])
    with pytest.raises(InputError, match='shape'):
        solver.solve_batch(np.zeros((4, 2, 3)), np.zeros((3, 2, 3)), [0, 1, 0])


def test_solve_pixels_matches_rays_and_checks_k():
    rng = np.random.default_rng(4)
    rotation, translation, points, rays, down = make_problem(rng)
    k = np.array([[900.0, 0.5, 640.0], [0, 910.0, 480.0], [0, 0, 1.0]])
    uv = (rays @ k.T)[:, :2] / (rays @ k.T)[:, 2:]
    rot_err, trans_err = best_error(solver.solve_pixels(uv, k.reshape(-1), points, down),
                                    rotation, translation)
    assert rot_err < 1e-9 and trans_err < 1e-9
    with pytest.raises(InputError, match='singular'):
        solver.solve_pixels(uv, np.zeros(9), points, down)
    assert np.allclose(solver.rays_from_pixels(uv, k), rays / rays[:, 2:])


def test_solution_json_form():
    rng = np.random.default_rng(8)
    rotation, translation, points, rays, down = make_problem(rng)
    out = solver.solve(rays, points, down)[0].to_dict()
    assert set(out) == {'R', 't', 'yaw'} and len(out['R']) == 9 and len(out['t']) == 3


def test_scalar_and_batch_forms_agree_including_degenerate_cases():
    rng = np.random.default_rng(31)
    rays, points, downs = [], [], []
    for k in range(300):
        _, _, p, r, d = make_problem(rng, vertical_spread=k % 3 != 0)
        rays.append(r)
        points.append(p)
        downs.append(d)
    for p, r, d in [([[0, 0, 0], [0, 0, 0]], [[0, 0, 1], [0.1, 0, 1]], [0, 1, 0]),
                    ([[1, 2, 0], [1, 2, 1]], [[0, 0, 1], [0, -0.2, 1]], [0, 1, 0]),
                    ([[0, 0, 0], [1, 0, 0]], [[0.1, 0.1, 1], [0.2, 0.2, 2]], [0, 1, 0]),
                    ([[0, 0, 0], [1, 0, 0]], [[-0.1, 0, 1], [0.1, 0, 1]], [0, 1, 0]),
                    ([[0, 0, 0], [1, 0, 0.5]], [[-0.1, 0, 1], [0.1, 0, 1]], [0, 1, 0]),
                    ([[0, 0, 0], [1, 0, 0]], [[-0.1, 0.1, 1], [0.1, 0.1, 1]], [0, 0, 0]),
                    ([[0, 0, 0], [1, 0, 0]], [[-0.1, 0.1, -1], [0.1, 0.1, 1]], [0, 1, 0]),
                    ([[0, 0, 0], [1, 0, 0]], [[0.0, -0.2, 1.0], [0.3, 0.2, 1.0]], [0, 1, 0]),
                    ([[0, 0, 0], [0.1, 0, 5]], [[-0.3, 0.1, 1.0], [0.3, 0.1, 1.0]], [0, 1, 0]),
                    ([[0, 0, 0], [1, 0, 0]], [[-0.1, 0.1, 1], [0.1, 0.1, 1]], [0, 0, -1]),
                    ([[0, 0, 0], [1, 0, 0]], [[-0.1, 0.1, 1], [0.1, 0.1, 1]], [0, 0, 1])]:
        points.append(np.asarray(p, float))
        rays.append(np.asarray(r, float))
        downs.append(np.asarray(d, float))
    result = solver.solve_batch(np.stack(rays), np.stack(points), np.stack(downs))
    assert len(set(result.status.tolist())) >= 8
    for k in range(len(rays)):
        try:
            single = solver.solve(rays[k], points[k], downs[k])
        except GeometryError as exc:
            assert result.status[k] != solver.OK and str(exc) == result.reason(k)
            continue
        batch = result.solutions(k)
        assert result.status[k] == solver.OK and len(single) == len(batch)
        for a, b in zip(single, batch):
            assert np.allclose(a.rotation, b.rotation, atol=1e-12)
            assert np.allclose(a.translation, b.translation, atol=1e-10)
            assert a.yaw == pytest.approx(b.yaw, abs=1e-12)
            assert np.allclose(a.depths, b.depths, rtol=1e-10)


@pytest.mark.parametrize('scale', [1e200, 1e-200, 1e-300, 1e300])
def test_scaled_down_and_rays_give_the_unit_solution_without_warnings(scale):
    """A direction of any finite nonzero length works (no overflow/underflow) in both forms."""
    rng = np.random.default_rng(12)
    rotation, translation, points, rays, down = make_problem(rng)
    unit = solver.solve(rays, points, down)
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        for got in (solver.solve(rays, points, down * scale),
                    solver.solve(rays * scale, points, down),
                    solver.solve_batch(rays[None] * scale, points,
                                       down * scale).solutions(0)):
            assert len(got) == len(unit)
            for a, b in zip(unit, got):
                assert np.allclose(a.rotation, b.rotation, atol=1e-12)
                assert np.allclose(a.translation, b.translation, atol=1e-9)


def test_emitter_coordinates_beyond_the_range_are_refused():
    """|coordinate| > MAX_COORDINATE_M: InputError (solve) / OUT_OF_RANGE (batch), no warning."""
    rays = [[-0.1, 0.1, 1.0], [0.1, 0.1, 1.0]]
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        for far in ([[0, 0, 0], [0, 1e300, 0]], [[0, 0, 0], [2e6, 0, 0]]):
            with pytest.raises(InputError, match='1,000,000 m'):
                solver.solve(rays, far, [0, 1.0, 0])
            result = solver.solve_batch(np.array([rays]), far, [0, 1.0, 0])
            assert result.status[0] == solver.OUT_OF_RANGE and not result.valid.any()
    assert solver.solve(rays, [[0, 0, 0], [1e6, 0, 0]], [0, 1.0, 0])  # the bound itself
