"""Lookup maps: tilt (eq. 7), camera choice (eq. 6), projection, and the fast rebuild."""
import math

from accelcal_ros.camera import distort_normalized, undistort_normalized
from accelcal_ros.camera.rig import Rig, RigCamera, ring_rig
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rot_x, rot_z
from accelcal_ros.panorama.lookup import LookupBuilder
from accelcal_ros.panorama.mosaic import MosaicLayout, OUTSIDE
from accelcal_ros.panorama.projection import PanoramaGeometry
from accelcal_ros.panorama.rig_projection import normalized_from_pixels, tilt_matrix
import cv2
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

ANGLE = st.floats(-0.6, 0.6)
LENS = (-0.12, 0.03, 0.0008, -0.0005, 0.001)


def _rig(**kwargs):
    args = {'count': 5, 'width': 320, 'height': 240, 'focal_px': 275.0, 'step_deg': 36.0,
            'distortion': LENS, 'mount_error_deg': 0.5, 'seed': 3}
    args.update(kwargs)
    return ring_rig(**args)


@settings(max_examples=40, deadline=None)
@given(ANGLE, ANGLE)
def test_tilt_is_paper_eq7_in_the_optical_frame(roll, pitch):
    """Default imu_to_camera: T = Rz(-roll) Rx(pitch), paper A's R_z(phi) R_x(theta)."""
    assert np.allclose(tilt_matrix(roll, pitch), rot_z(-roll) @ rot_x(pitch), atol=1e-12)


def test_tilt_of_a_camera_pitched_down_sees_the_horizon_above_centre():
    """Body pitched 10 deg nose-down (REP-103): a level ray appears 10 deg above the axis."""
    level_ray = np.array([0.0, 0.0, 1.0])  # panorama frame: straight ahead, horizontal
    c = tilt_matrix(0.0, math.radians(10.0)) @ level_ray
    assert math.degrees(math.atan2(-c[1], c[2])) == pytest.approx(10.0)


def test_tilt_with_a_rotated_reference_camera():
    """A camera yawed 20 deg right of body +x: the panorama's azimuth 0 is its heading."""
    c = DEFAULT_IMU_TO_CAMERA @ rot_z(math.radians(-20.0)).T
    t = tilt_matrix(0.0, 0.0, c)
    assert np.allclose(t, np.eye(3), atol=1e-12)
    # tilted down 5 deg w.r.t. the body: the level horizon is 5 deg above its axis
    c_down = rot_x(math.radians(5.0)) @ DEFAULT_IMU_TO_CAMERA
    ray = tilt_matrix(0.0, 0.0, c_down) @ np.array([0.0, 0.0, 1.0])
    assert math.degrees(math.atan2(-ray[1], ray[2])) == pytest.approx(5.0)


@settings(max_examples=30, deadline=None)
@given(st.floats(-0.7, 0.7), st.floats(-0.5, 0.5))
def test_distortion_matches_opencv_and_inverts(x, y):
    """distort_normalized is OpenCV's model; undistort_normalized inverts it."""
    k = np.eye(3)
    expected = cv2.projectPoints(np.array([[x, y, 1.0]]), np.zeros(3), np.zeros(3), k,
                                 np.array(LENS))[0].reshape(2)
    got = distort_normalized(np.array(x), np.array(y), LENS)
    assert np.allclose(got, expected, atol=1e-12)
    back = undistort_normalized(got[0], got[1], LENS)
    assert np.allclose(back, [x, y], atol=1e-10)


def test_camera_choice_is_eq6_and_projection_round_trips():
    """Labels maximise the axis dot product; camera pixels map back to themselves."""
    rig = _rig()
    builder = LookupBuilder(rig, PanoramaGeometry(720, 480))
    q = builder.camera_rotations(0.05, 0.2)
    rng = np.random.default_rng(0)
    rays = rng.normal(size=(5000, 3))
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    label, x, y, side = builder.evaluate(rays, q)
    axes = np.stack([qi[2] for qi in q])
    assert np.array_equal(label, np.argmax(rays @ axes.T, axis=1))
    for i, cam in enumerate(rig.cameras):
        px = rng.uniform(0, cam.width - 1, 200)
        py = rng.uniform(0, cam.height - 1, 200)
        xn, yn = normalized_from_pixels(cam, px, py)
        cam_rays = np.stack([xn, yn, np.ones_like(xn)], axis=1)
        pano_rays = cam_rays @ q[i]  # Q_i^T c
        pano_rays /= np.linalg.norm(pano_rays, axis=1, keepdims=True)
        _, bx, by, bside = builder.evaluate(pano_rays, q, only=i)
        assert np.all(bside == 0)
        assert np.abs(bx - px).max() < 2e-3 and np.abs(by - py).max() < 2e-3


def test_rays_behind_or_far_outside_a_distorted_camera_are_rejected():
    """A strongly distorted lens must not fold far-off rays back into its frame."""
    k = np.array([[200.0, 0, 159.5], [0, 200.0, 119.5], [0, 0, 1]])
    cam = RigCamera('fish', 320, 240, k, np.array([-0.35, 0.08, 0, 0, 0]), np.eye(3))
    builder = LookupBuilder(Rig((cam,)), PanoramaGeometry(720, 480, 360.0, 170.0))
    exact = builder.build_exact(0.0, 0.0)
    seen = exact[..., 0] != OUTSIDE
    rays = builder.geometry.rays(np.arange(720)[None, :], np.arange(480)[:, None])
    angle = np.degrees(np.arccos(np.clip(rays[..., 2], -1, 1)))
    corner = np.degrees(np.arctan(np.hypot(*normalized_from_pixels(cam, 0.0, 0.0))))
    assert seen.any() and angle[seen].max() <= corner + 1.0


def test_mosaic_layout_wraps_and_keeps_gaps():
    """Images sit left to right with gaps, wrapping before the fixed-point limit."""
    rig = _rig(width=400, height=300)
    layout = MosaicLayout.for_rig(rig, gap=10, limit=1000)
    assert layout.offsets[:3] == ((10, 10), (420, 10), (10, 320))
    assert layout.width <= 1000 and layout.height == 10 + 3 * 310


def _white_render(builder, rig, maps):
    white = np.zeros((builder.layout.height, builder.layout.width), np.uint8)
    for (x0, y0), cam in zip(builder.layout.offsets, rig.cameras):
        white[y0:y0 + cam.height, x0:x0 + cam.width] = 255
    return [cv2.remap(white, m, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
            for m in maps]


@pytest.mark.parametrize('projection, size, step', [
    ('spherical', (720, 480), 16), ('cylindrical', (700, 500), 16), ('spherical', (720, 480), 8),
    ('spherical', (723, 481), 16), ('spherical', (720, 480), 20), ('cylindrical', (720, 480), 12)])
def test_fast_rebuild_matches_exact_within_tolerance(projection, size, step):
    """
    Coarse grid + interpolation equals the exact map within tolerance_px everywhere.

    Steps 20, 16/8 and 12 refine mixed cells by sub-blocks of 5, 4 and 3 pixels; 14
    (cylindrical 700 wide) evaluates them pixel by pixel; 723 is not a multiple of 16.
    """
    rig = _rig()
    geometry = PanoramaGeometry(size[0], size[1], 180.0, 120.0, projection)
    builder = LookupBuilder(rig, geometry, grid_step=step, tolerance_px=0.1)
    rng = np.random.default_rng(7)
    for roll, pitch in [(0.0, 0.0), (0.05, 0.26)] + list(rng.uniform(-0.35, 0.35, (3, 2))):
        exact = builder.build_exact(roll, pitch)
        fast = builder.build_fast(roll, pitch).copy()
        r0, r1 = builder.band
        assert np.all(exact[:r0, :, 0] == OUTSIDE) and np.all(exact[r1:, :, 0] == OUTSIDE)
        seen = exact[r0:r1, :, 0] != OUTSIDE
        error = np.abs(fast[r0:r1] - exact[r0:r1]).max(axis=-1)[seen]
        assert error.max() <= 0.1 + 1e-4, (roll, pitch, error.max())
        # where no camera sees a pixel, the fast map samples black (gap or outside)
        a, b = _white_render(builder, rig, [exact[r0:r1], np.ascontiguousarray(fast[r0:r1])])
        assert np.array_equal(a > 0, b > 0) or (np.abs(a.astype(int) - b) > 40).sum() == 0


@pytest.mark.parametrize('pitch_deg', [-80.0, -30.0, 0.0, 45.0, 85.0])
def test_seen_rows_hold_every_seen_pixel_even_with_a_pole_in_a_frame(pitch_deg):
    """The row range skipped by the fast builder holds no pixel any camera sees."""
    rig = _rig()
    geometry = PanoramaGeometry(720, 480, 180.0, 180.0)
    builder = LookupBuilder(rig, geometry, grid_step=16)
    pitch = math.radians(pitch_deg)
    exact = builder.build_exact(0.1, pitch)
    seen_rows = np.nonzero((exact[..., 0] != OUTSIDE).any(axis=1))[0]
    r0, r1 = builder.seen_rows(builder.camera_rotations(0.1, pitch))
    assert seen_rows.size and r0 <= seen_rows[0] and seen_rows[-1] < r1
    if abs(pitch_deg) >= 80.0:  # a pole inside the reference frame: the range reaches it
        assert (r0 == 0) if pitch_deg < 0 else (r1 == geometry.height)
    else:  # and it is tight otherwise: within a few rows of what is seen
        assert seen_rows[0] - r0 <= 8 and r1 - seen_rows[-1] <= 9
    fast = builder.build_fast(0.1, pitch)
    b0, b1 = builder.band
    seen = exact[b0:b1, :, 0] != OUTSIDE
    assert np.abs(fast[b0:b1] - exact[b0:b1]).max(axis=-1)[seen].max() <= 0.1 + 1e-4


def test_fast_rebuild_error_bound_is_the_tolerance_parameter():
    """A looser tolerance gives more interpolated cells and an error still within it."""
    rig = _rig()
    geometry = PanoramaGeometry(720, 480)
    strict = LookupBuilder(rig, geometry, grid_step=32, tolerance_px=0.02)
    loose = LookupBuilder(rig, geometry, grid_step=32, tolerance_px=0.5)
    exact = strict.build_exact(0.1, 0.2)
    seen = exact[..., 0] != OUTSIDE
    for builder, tol in ((strict, 0.02), (loose, 0.5)):
        fast = builder.build_fast(0.1, 0.2)
        assert np.abs(fast - exact).max(axis=-1)[seen].max() <= tol + 1e-4
    assert loose.last_stats['pure_cells'] > strict.last_stats['pure_cells']
