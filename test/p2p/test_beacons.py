"""Beacon detection and rendered ground truth: render -> detect -> undistort -> solve."""
from accelcal_ros.camera import CameraModel
from accelcal_ros.errors import InputError
from accelcal_ros.p2p import beacons, render, solver
import numpy as np
import pytest

EMITTERS = np.array([[-0.3, -0.4, 0.0], [0.35, 0.45, 0.05]])


def scene(roll_deg=4.0, pitch_deg=18.0, yaw_deg=179.0, position=(3.0, 0.3, 1.4), dist=None):
    camera = CameraModel.from_fov(1280, 960, 60.0, dist_coeffs=dist)
    rotation, translation = render.pose_from_camera_attitude(
        *np.radians([roll_deg, pitch_deg, yaw_deg]), position)
    return camera, rotation, translation


def test_pose_from_camera_attitude_matches_yaw_and_position():
    camera, rotation, translation = scene(yaw_deg=-120.0)
    assert solver.yaw_from_rotation(rotation) == pytest.approx(np.radians(-120.0))
    assert np.allclose(-rotation.T @ translation, [3.0, 0.3, 1.4])


@pytest.mark.parametrize('dist', [None, [-0.25, 0.08, 0.001, -0.002, -0.01]])
def test_rendered_ground_truth_pose(dist):
    """Blurred, noisy rendered image at a known pose: detection and solver give the pose."""
    camera, rotation, translation = scene(dist=dist)
    image, uv_true, depth = render.render_emitters(EMITTERS, rotation, translation, camera,
                                                   sigma_px=1.6, peak=240, blur_sigma_px=0.8,
                                                   noise_std=3.0, seed=1)
    assert np.all(depth > 0) and image.dtype == np.uint8 and image.shape == (960, 1280)
    down = rotation @ [0, 0, -1.0]
    detection = beacons.detect_beacons(image, beacons.DetectorSettings(threshold=60),
                                       camera, down=down)
    assert detection.ok, detection.reason
    assert np.abs(detection.uv - uv_true).max() < 0.05     # sub-pixel centroids
    true_rays = EMITTERS @ rotation.T + translation
    true_rays = true_rays / true_rays[:, 2:]
    assert np.abs(detection.rays - true_rays).max() < 1e-4
    [pose] = solver.solve(detection.rays, EMITTERS, down)
    assert np.degrees(abs(pose.yaw - solver.yaw_from_rotation(rotation))) < 0.02
    assert abs(pose.range_m / np.linalg.norm(translation) - 1.0) < 1e-3
    assert np.linalg.norm(pose.camera_position - [3.0, 0.3, 1.4]) < 5e-3
    quality = detection.quality()
    assert quality['candidates'] == 2 and quality['separation_px'] > 100


def test_centroids_are_sub_pixel_on_random_positions():
    rng = np.random.default_rng(0)
    uv = rng.uniform([20, 20], [300, 220], size=(20, 2))
    errors = []
    for a, b in uv.reshape(-1, 2, 2):
        spots = render.draw_spots((240, 320), [a, b], sigma_px=1.2, peak=250)
        noisy = spots + rng.standard_normal(spots.shape) * 2.0
        image = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
        found = beacons.detect_beacons(image, beacons.DetectorSettings(threshold=50))
        if np.linalg.norm(a - b) < 10:
            continue
        assert found.ok, found.reason
        got = found.uv[np.argsort(found.uv[:, 0])]
        want = np.array([a, b])[np.argsort([a[0], b[0]])]
        errors.append(np.abs(got - want).max())
    assert max(errors) < 0.06


def test_saturated_blobs_are_centred_and_counted():
    spots = render.draw_spots((100, 200), [[50.3, 40.6], [150.7, 60.2]], sigma_px=2.5,
                              peak=900)
    image = np.clip(spots, 0, 255).astype(np.uint8)
    found = beacons.detect_beacons(image)
    assert found.ok
    assert np.abs(found.uv - [[50.3, 40.6], [150.7, 60.2]]).max() < 0.05
    assert found.blobs[0].saturated_px > 5


def test_zero_one_three_candidates_give_reasons():
    dark = np.full((120, 160), 10, np.uint8)
    zero = beacons.detect_beacons(dark)
    assert not zero.ok and 'no pixel above threshold' in zero.reason
    assert 'brightest 10' in zero.reason
    one = render.draw_spots((120, 160), [[40.0, 60.0]], 1.5, 240).astype(np.uint8)
    res = beacons.detect_beacons(one)
    assert not res.ok and 'one emitter candidate' in res.reason
    three = render.draw_spots((120, 160), [[20, 20], [80, 60], [140, 100]], 1.5, 240)
    res = beacons.detect_beacons(three.astype(np.uint8))
    assert not res.ok and '3 emitter candidates' in res.reason and res.uv is None


def test_size_and_brightness_limits_reject_blobs():
    image = render.draw_spots((120, 200), [[40, 60], [120, 60]], 1.5, 240)
    image[10:60, 150:195] = 250                        # a large bright patch (a window)
    image = image.astype(np.uint8)
    found = beacons.detect_beacons(image, beacons.DetectorSettings(max_area_px=200))
    assert found.ok and found.rejected['large'] == 1
    dim = render.draw_spots((120, 200), [[40, 60], [120, 60]], 1.5, 240)
    dim += render.draw_spots((120, 200), [[160, 100]], 1.5, 180) - 8.0
    found = beacons.detect_beacons(dim.astype(np.uint8),
                                   beacons.DetectorSettings(threshold=100, min_peak=220))
    assert found.ok and found.rejected['dim'] == 1
    speckle = np.zeros((50, 50), np.uint8)
    speckle[::4, ::4] = 255
    limits = beacons.DetectorSettings(min_area_px=1, max_candidates=10)
    found = beacons.detect_beacons(speckle, limits)
    assert not found.ok and 'max_candidates' in found.reason
    found = beacons.detect_beacons(speckle, beacons.DetectorSettings(min_area_px=2))
    assert not found.ok and 'small' in found.reason


def test_ordering_options():
    big_left = render.draw_spots((100, 200), [[40, 50]], 3.0, 240)
    small_right = render.draw_spots((100, 200), [[150, 30]], 1.3, 240)
    image = np.maximum(big_left, small_right).astype(np.uint8)
    uv = {}
    for order in beacons.ORDERS:
        found = beacons.detect_beacons(image, beacons.DetectorSettings(order=order))
        assert found.ok
        uv[order] = found.uv[0].round()
    assert tuple(uv['left_to_right']) == (40, 50) and tuple(uv['right_to_left']) == (150, 30)
    assert tuple(uv['top_to_bottom']) == (150, 30) and tuple(uv['bottom_to_top']) == (40, 50)
    assert tuple(uv['larger_first']) == (40, 50) and tuple(uv['smaller_first']) == (150, 30)
    assert tuple(uv['brighter_first']) == (40, 50) and tuple(uv['dimmer_first']) == (150, 30)


def test_left_to_right_follows_the_horizon_when_rolled():
    """Camera rolled 120 deg: image columns flip, the gravity-aware order does not."""
    camera, rotation, translation = scene(roll_deg=120.0, pitch_deg=15.0, yaw_deg=30.0,
                                          position=(-4.0, -2.0, 1.0))
    points = np.array([[0.0, 0.6, 0.0], [0.0, -0.6, 0.0]])   # M1 left of M2 seen from -x
    rotation, translation = render.pose_from_camera_attitude(
        np.radians(120.0), np.radians(15.0), 0.0, (-4.0, 0.0, 1.0))
    image, uv, _ = render.render_emitters(points, rotation, translation, camera, noise_std=0)
    assert uv[0, 0] > uv[1, 0]            # upside down-ish: M1 is right in the image
    down = rotation @ [0, 0, -1.0]
    found = beacons.detect_beacons(image, camera=camera, down=down)
    assert np.allclose(found.uv, uv, atol=0.05)
    naive = beacons.detect_beacons(image, camera=camera)
    assert np.allclose(naive.uv, uv[::-1], atol=0.05)


def test_undistortion_models():
    k = np.array([[800.0, 0, 640], [0, 800.0, 480], [0, 0, 1]])
    rays = np.array([[0.3, -0.2, 1.0], [-0.5, 0.4, 1.0]])
    import cv2

    for d in ([-0.3, 0.1, 0.001, 0.002, -0.02],
              [-0.3, 0.1, 0.001, 0.002, -0.02, 0.01, 0.0, 0.0]):
        d = np.array(d)
        uv, _ = cv2.projectPoints(rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), k, d)
        got, ideal = beacons.undistort_pixels(uv.reshape(-1, 2), CameraModel(0, 0, k, d))
        assert np.abs(got - rays).max() < 1e-7
        assert np.allclose(ideal, (rays @ k.T)[:, :2], atol=1e-4)
    fisheye = np.array([0.05, -0.01, 0.002, 0.0])
    uv = cv2.fisheye.distortPoints(rays[:, None, :2].copy(), k, fisheye)
    got, _ = beacons.undistort_pixels(uv.reshape(-1, 2),
                                      CameraModel(0, 0, k, fisheye, 'equidistant'))
    assert np.abs(got - rays).max() < 1e-9
    got, _ = beacons.undistort_pixels((rays @ k.T)[:, :2], CameraModel(0, 0, k, np.zeros(5)))
    assert np.abs(got - rays).max() < 1e-12
    # past the radius where the distortion folds back there is no ray: refused, not solved
    barrel = CameraModel(0, 0, k, np.array([-0.6, 0.0, 0.0, 0.0, 0.0]))
    with pytest.raises(InputError, match=r"pixel \(1280, 960\) is outside the lens model's"):
        beacons.undistort_pixels(np.array([[700.0, 500.0], [1280.0, 960.0]]), barrel)
    with pytest.raises(InputError, match='valid range'):
        beacons.undistort_pixels(np.array([[1600.0, 1200.0]]), barrel)
    with pytest.raises(InputError, match='not supported'):
        CameraModel(0, 0, k, fisheye, 'weird')
    with pytest.raises(InputError, match='coefficients'):
        CameraModel(0, 0, k, np.ones(3))


def test_colour_and_bad_images():
    spots = render.draw_spots((80, 120), [[30, 40], [90, 40]], 1.5, 240).astype(np.uint8)
    colour = np.dstack([spots, spots, spots])
    assert beacons.detect_beacons(colour).ok
    with pytest.raises(InputError, match='8-bit'):
        beacons.detect_beacons(spots.astype(np.float32))
    with pytest.raises(InputError, match='shape'):
        beacons.detect_beacons(np.zeros((4, 4, 2), np.uint8))
    with pytest.raises(InputError, match='order'):
        beacons.DetectorSettings(order='sideways')
    with pytest.raises(InputError, match='area'):
        beacons.DetectorSettings(min_area_px=10, max_area_px=5)
    with pytest.raises(InputError, match='sigma'):
        render.render_emitters(EMITTERS, np.eye(3), [0, 0, 5.0],
                               CameraModel.from_fov(), sigma_px=0)


def test_emitter_behind_camera_is_not_drawn():
    camera = CameraModel.from_fov(320, 240, 60.0)
    points = np.array([[0.0, 0.0, 5.0], [0.0, 0.0, -5.0]])
    image, uv, depth = render.render_emitters(points, np.eye(3), np.zeros(3), camera,
                                              noise_std=0)
    assert depth[1] < 0
    found = beacons.detect_beacons(image)
    assert not found.ok and 'one emitter candidate' in found.reason
