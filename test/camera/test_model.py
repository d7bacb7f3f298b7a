"""The one camera model against OpenCV, on random ground truth (every lens model)."""
import warnings

from accelcal_ros.camera import (camera_model_from_mapping, CameraModel, distort_normalized,
                                 undistort_normalized)
from accelcal_ros.camera import distortion
from accelcal_ros.errors import InputError
import cv2
import numpy as np
import pytest

K = np.array([[612.0, 0.0, 331.2], [0.0, 598.5, 236.9], [0.0, 0.0, 1.0]])
SKEWED = K + [[0.0, 0.4, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
LENSES = {
    'none': ('plumb_bob', []),
    'plumb_bob': ('plumb_bob', [-0.28, 0.09, 0.0011, -0.0007, -0.012]),
    'plumb_bob_4': ('plumb_bob', [-0.21, 0.04, -0.0009, 0.0004]),
    'rational_polynomial': ('rational_polynomial',
                            [0.31, -0.12, 0.0008, 0.0005, 0.02, 0.62, -0.05, 0.03]),
    'equidistant': ('equidistant', [-0.021, 0.004, -0.0012, 0.0003]),
}


def _truth(seed, count=500, half_angle_deg=35.0):
    """Random unit rays within ``half_angle_deg`` of the axis (optical frame)."""
    rng = np.random.default_rng(seed)
    theta = np.radians(half_angle_deg) * np.sqrt(rng.uniform(0.0, 1.0, count))
    az = rng.uniform(-np.pi, np.pi, count)
    return np.stack([np.sin(theta) * np.cos(az), np.sin(theta) * np.sin(az), np.cos(theta)],
                    axis=1)


def _opencv_project(points, model, d, k):
    if model == 'equidistant':
        alpha = k[0, 1] / k[0, 0]
        uv, _ = cv2.fisheye.projectPoints(points.reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
                                          k, np.asarray(d, float), alpha=alpha)
    else:
        uv, _ = cv2.projectPoints(points.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), k,
                                  np.asarray(d, float))
    return uv.reshape(-1, 2)


@pytest.mark.parametrize('lens', sorted(LENSES))
def test_project_and_unproject_match_opencv(lens):
    """
    project() is OpenCV's; unproject() recovers the true rays; undistort matches cv2.

    OpenCV's pinhole functions ignore the skew K[0, 1] (its fisheye ones apply it as
    alpha): the model applies it always, so the skew is tested with the fisheye only.
    """
    model, d = LENSES[lens]
    k = SKEWED if model == 'equidistant' else K
    camera = CameraModel(640, 480, k, d, model)
    rays = _truth(sum(map(ord, lens)))
    points = rays * np.random.default_rng(1).uniform(0.5, 30.0, (len(rays), 1))
    expected = _opencv_project(points, model, d, k)
    got = camera.project(points)
    assert np.abs(got - expected).max() < 1e-6  # OpenCV works in float64 too
    back = camera.unproject(expected)
    assert np.abs(back - rays).max() < 1e-9
    assert np.allclose(np.linalg.norm(back, axis=1), 1.0)
    # undistortion against OpenCV's own, iterated to convergence (without skew: the
    # fisheye undistortPoints ignores it)
    plain = CameraModel(640, 480, K, d, model)
    pixels = plain.project(points)
    xy = plain.normalized_from_pixels(pixels[:, 0], pixels[:, 1])
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)
    if model == 'equidistant':
        ref = cv2.fisheye.undistortPoints(pixels.reshape(-1, 1, 2), plain.K,
                                          np.asarray(d, float), criteria=criteria)
    else:
        iterated = getattr(cv2, 'undistortPointsIter', None)  # OpenCV 4; 5 has criteria=
        args = (pixels.reshape(-1, 1, 2), plain.K, np.asarray(d, float))
        ref = (iterated(*args, np.eye(3), np.eye(3), criteria) if iterated else
               cv2.undistortPoints(*args, R=np.eye(3), P=np.eye(3), criteria=criteria))
    assert np.abs(np.stack(xy, axis=1) - ref.reshape(-1, 2)).max() < 1e-6
    assert np.allclose(np.stack(xy, axis=1), rays[:, :2] / rays[:, 2:], atol=1e-10)


def test_distortion_functions_invert_each_other_vectorised():
    """distort/undistort on normalised coordinates: any shape, one set of coefficients."""
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-0.5, 0.5, (2, 4, 50))
    for model, d in LENSES.values():
        d = CameraModel(640, 480, K, d, model).D
        xd, yd = distort_normalized(x, y, d, model)
        assert xd.shape == x.shape
        bx, by = undistort_normalized(xd, yd, d, model)
        assert np.abs(bx - x).max() < 1e-10 and np.abs(by - y).max() < 1e-10


def test_a_few_points_take_the_float_path_with_the_same_result():
    """Up to SCALAR_POINTS points are inverted on floats: equal to the array path."""
    rng = np.random.default_rng(5)
    x, y = rng.uniform(-0.5, 0.5, (2, 40))
    for model, d in LENSES.values():
        d = CameraModel(640, 480, K, d, model).D
        xd, yd = distort_normalized(x, y, d, model)
        all_x, all_y = undistort_normalized(xd, yd, d, model)
        for k in range(0, 40, 3):
            few_x, few_y = undistort_normalized(xd[k:k + 3], yd[k:k + 3], d, model)
            assert np.abs(few_x - all_x[k:k + 3]).max() < 1e-13
            assert np.abs(few_y - all_y[k:k + 3]).max() < 1e-13
        one_x, one_y = undistort_normalized(xd[0], yd[0], d, model)
        assert np.shape(one_x) == () and abs(float(one_x) - all_x[0]) < 1e-13


def test_points_behind_the_camera_give_nan_and_one_point_works():
    """A point at z <= 0 has no pixel; a single (3,) point gives one (1, 2) row."""
    camera = CameraModel(640, 480, K)
    uv = camera.project(np.array([[0.1, 0.2, -1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 2.0]]))
    assert np.isnan(uv[:2]).all() and np.allclose(uv[2], K[:2, 2])
    assert camera.project([0.0, 0.0, 1.0]).shape == (1, 2)
    assert np.allclose(camera.unproject(K[:2, 2]), [[0.0, 0.0, 1.0]])


def test_fisheye_beyond_ninety_degrees_unprojects_behind():
    """An equidistant lens sees past 90 degrees: unproject gives z < 0 there."""
    d = [0.0, 0.0, 0.0, 0.0001]
    camera = CameraModel(1000, 1000, np.array([[200.0, 0, 499.5], [0, 200.0, 499.5],
                                               [0, 0, 1.0]]), d, 'equidistant')
    theta = np.radians(100.0)
    radius_px = 200.0 * theta * (1 + 0.0001 * theta ** 8)
    ray = camera.unproject([499.5 + radius_px, 499.5])[0]
    assert np.allclose(ray, [np.sin(theta), 0.0, np.cos(theta)], atol=1e-9)


def test_mapping_round_trip_and_ros_calibration_yaml():
    """to_mapping/camera_model_from_mapping round-trip; ROS calibration YAML reads too."""
    for model, d in LENSES.values():
        camera = CameraModel(640, 480, K, d, model)
        again = camera_model_from_mapping(camera.to_mapping())
        assert np.array_equal(again.K, camera.K) and np.array_equal(again.D, camera.D)
        assert again.distortion_model == camera.distortion_model
    ros = {'image_width': 640, 'image_height': 480, 'camera_name': 'cam',
           'camera_matrix': {'rows': 3, 'cols': 3, 'data': K.reshape(-1).tolist()},
           'distortion_model': 'plumb_bob',
           'distortion_coefficients': {'rows': 1, 'cols': 5, 'data': [0.1, 0, 0, 0, 0]}}
    camera = camera_model_from_mapping(ros)
    assert camera.size == (640, 480) and camera.D.tolist() == [0.1, 0, 0, 0, 0]


@pytest.mark.parametrize('change, words', [
    ({'K': [0, 0, 0, 0, 0, 0, 0, 0, 0]}, 'fx, fy > 0'),
    ({'K': [500, 0, 320, 0, -500, 240, 0, 0, 1]}, 'fx, fy > 0'),
    ({'K': [500, 0, 320, 0, 500, 240, 0, 0]}, '9 values'),
    ({'K': [500, 0, float('nan'), 0, 500, 240, 0, 0, 1]}, 'NaN'),
    ({'K': 'abc'}, 'list of numbers'),
    ({'D': [0.1, 0.2, 0.3]}, '4, 5 or 8'),
    ({'D': [0.1, float('inf'), 0, 0]}, 'NaN or infinity'),
    ({'D': [0.1, 0.2, 0.0, 0.0, 0.0], 'distortion_model': 'equidistant'}, '4 coefficients'),
    ({'D': [0.1, 0.0, 0.0, 0.0, 0.0], 'distortion_model': 'weird'}, 'not supported'),
    ({'width': 0}, 'width must be an integer'),
    ({'height': 2.5}, 'height must be an integer'),
    ({'width': True}, 'width must be an integer'),
])
def test_bad_values_are_refused_naming_the_key(change, words):
    """Every invalid field gives one InputError naming the camera and the key."""
    entry = dict(CameraModel(640, 480, K).to_mapping(), **change)
    with pytest.raises(InputError, match=words) as info:
        camera_model_from_mapping(entry, 'camera 2 (left)')
    assert str(info.value).startswith('camera 2 (left): ')


def test_camera_info_fields():
    """A CameraInfo with K scaled, no D or an unknown model with zero D is accepted."""
    camera = CameraModel.from_camera_info((2 * K).reshape(-1), [], '', 640, 480)
    assert np.allclose(camera.K, K) and camera.distortion_model == 'plumb_bob'
    assert not CameraModel.from_camera_info(K.reshape(-1), [0.0] * 5, 'x', 0, 0).has_distortion()
    with pytest.raises(InputError, match='camera_info K'):
        CameraModel.from_camera_info([0.0] * 9, [], 'plumb_bob', 640, 480)


STRONG_LENSES = dict(LENSES, barrel=('plumb_bob', [-0.6, 0.0, 0.0, 0.0, 0.0]),
                     wavy=('plumb_bob', [-0.3, 0.1, 0.001, 0.002, -0.02]),
                     rational_fold=('rational_polynomial',
                                    [-0.3, 0.1, 0.001, 0.002, -0.02, 0.01, 0.0, 0.0]),
                     fisheye_fold=('equidistant', [-0.2, 0.0, 0.0, 0.0]))


def _sampled_fold(d, model):
    """Ground truth of monotonic_limit2: the first radius where the radial map decreases."""
    r = np.linspace(0.0, 20.0, 2000001)
    if model == 'equidistant':
        mapped = distortion.distort_equidistant_angle(r, d)
    else:  # along +x, tangential terms left out: r s(r^2)
        mapped = distort_normalized(r, 0.0 * r, np.r_[d[:2], 0.0, 0.0, d[4:]], model)[0]
    falls = np.nonzero(np.diff(mapped) <= 0.0)[0]
    return r[falls[0]] if falls.size else np.inf


@pytest.mark.parametrize('lens', sorted(STRONG_LENSES))
def test_undistortion_round_trips_valid_points_on_both_paths(lens):
    """Distort random points within the monotonic range, undistort: back within 1e-10."""
    model, d = STRONG_LENSES[lens]
    d = CameraModel(640, 480, K, d, model).D
    limit = np.sqrt(distortion.monotonic_limit2(tuple(d), model))
    assert limit == pytest.approx(_sampled_fold(d, model), abs=2e-5, rel=1e-6)
    rng = np.random.default_rng(sum(map(ord, lens)))
    radius = min(limit, 1.4) * 0.98 * np.sqrt(rng.uniform(0.0, 1.0, 400))
    if model == 'equidistant':
        radius = np.tan(radius)  # limit is an angle (rad)
    azimuth = rng.uniform(-np.pi, np.pi, 400)
    x, y = radius * np.cos(azimuth), radius * np.sin(azimuth)
    xd, yd = distort_normalized(x, y, d, model)
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        bx, by = undistort_normalized(xd, yd, d, model)                  # array path
        pairs = [undistort_normalized(xd[k:k + 2], yd[k:k + 2], d, model)  # float path
                 for k in range(0, 400, 2)]
    scale = np.maximum(1.0, radius)
    assert np.abs((bx - x) / scale).max() < 1e-10 and np.abs((by - y) / scale).max() < 1e-10
    assert np.abs(np.concatenate([p[0] for p in pairs]) - bx).max() < 1e-12


def test_pixels_without_a_real_ray_are_nan_not_a_wrong_answer():
    """
    Past the fold (no ray, or only a ray on the folded branch), undistortion gives NaN.

    k1 = -0.6: r (1 - 0.6 r^2) peaks at r = 0.745 (distorted radius 0.497). (0.8, 0.6)
    has no preimage (Newton never converges); (1.2, 0.9) has one only on the folded
    branch (r = 1.78, where the radial factor is negative): the old code returned both.
    """
    d = [-0.6, 0.0, 0.0, 0.0, 0.0]
    xd, yd = np.array([0.8, 1.2, 0.2]), np.array([0.6, 0.9, 0.1])
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        for n in (1, 3):                                        # float and array paths
            x, y = undistort_normalized(np.tile(xd, n * 3), np.tile(yd, n * 3), d)
            assert np.isnan(x[:2]).all() and np.isnan(y[:2]).all(), x
            assert np.isfinite(x[2::3]).all()
            assert np.isnan(x[0::3]).all() and np.isnan(x[1::3]).all()
        camera = CameraModel(0, 0, np.array([[800.0, 0, 640], [0, 800.0, 480], [0, 0, 1]]), d)
        rays = camera.unproject([[1280.0, 960.0], [1600.0, 1200.0], [700.0, 500.0]])
        assert np.isnan(rays[:2]).all() and np.isfinite(rays[2]).all()
        back = camera.project(rays[2:] * 3.0)
        assert np.abs(back - [[700.0, 500.0]]).max() < 1e-9
        # a fisheye past its theta_d maximum (k1 = -0.3: 0.703 at 1.054 rad)
        theta, _, _ = distortion.undistort_equidistant_angle(np.array([0.9, 0.5]),
                                                             np.zeros(2), [-0.3, 0, 0, 0])
        assert np.isnan(theta[0]) and abs(distortion.distort_equidistant_angle(
            theta[1], [-0.3, 0, 0, 0]) - 0.5) < 1e-12
        # too few iterations to converge is not a valid answer either
        x, _ = undistort_normalized(np.array([0.49] * 10), np.zeros(10), d, iterations=2)
        assert np.isnan(x).all()
        assert np.isnan(undistort_normalized(np.nan, 0.0, d)[0])


def test_monotonic_limit_of_rational_and_undistorted_models():
    """No radial terms: no limit; a vanishing rational denominator ends the range."""
    assert distortion.monotonic_limit2((0.0, 0.0, 0.001, 0.002, 0.0)) == np.inf
    assert distortion.monotonic_limit2((0.1, 0.01, 0, 0, 0.001)) == np.inf
    # 1 - u = 0 at u = 1 with a numerator that keeps rising: the pole is the end
    assert distortion.monotonic_limit2((0.0, 0, 0, 0, 0, -1.0, 0, 0)) == pytest.approx(1.0)
