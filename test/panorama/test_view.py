"""Levelled views (personal regions of interest) against rendered ground truth."""
import math

from accelcal_ros.camera.rig import ring_rig
from accelcal_ros.errors import InputError
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rot_x, rot_z
from accelcal_ros.panorama import render, view as view_module
from accelcal_ros.panorama.mosaic import OUTSIDE
from accelcal_ros.panorama.view import LevelledView, ViewMosaic
from accelcal_ros.panorama.view_pose import (horizon_row, MAX_VIEW_SIDE_PX, view_camera_matrix,
                                             view_rotation, ViewPose)
import numpy as np
import pytest

LENS = (-0.1, 0.02, 0.0005, -0.0003, 0.0)
TILTED = rot_x(math.radians(7.0)) @ DEFAULT_IMU_TO_CAMERA @ rot_z(math.radians(-15.0)).T


@pytest.fixture(scope='module')
def scene():
    """Return the equirectangular texture the cameras are rendered from (0.2 deg/texel)."""
    return render.make_scene(1800, 900, seed=3)


def _rig(imu_to_camera=None):
    return ring_rig(5, 320, 240, 275.0, 36.0, distortion=LENS, mount_error_deg=0.5, seed=2,
                    imu_to_camera=imu_to_camera)


def pinhole_truth(scene, width, height, pose, imu_to_camera=DEFAULT_IMU_TO_CAMERA):
    """Return the scene's own pinhole view: every pixel's ray sampled straight from the texture."""
    k = view_camera_matrix(width, height, pose.fov_h_rad)
    ys, xs = np.mgrid[0:height, 0:width].astype(float)
    rays = np.stack([(xs - k[0, 2]) / k[0, 0], (ys - k[1, 2]) / k[1, 1], np.ones_like(xs)], -1)
    in_panorama = rays @ view_rotation(pose.azimuth_rad, pose.elevation_rad).T
    return render.sample_scene(scene, in_panorama @ render.panorama_frame_to_level(
        imu_to_camera).T)


def _seen(view, mosaic):
    """Pixels whose whole bilinear support lies on camera pixels (eroded by one)."""
    import cv2

    white = np.zeros(mosaic.image.shape[:2], np.uint8)
    for (x0, y0), cam in zip(mosaic.layout.offsets, view.rig.cameras):
        white[y0:y0 + cam.height, x0:x0 + cam.width] = 255
    seen = cv2.remap(white, view.lookup(), None, cv2.INTER_LINEAR) == 255
    return cv2.erode(seen.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)


class _ViewRows:
    """What :func:`render.horizon_rows` needs of a geometry, for a view's image."""

    def __init__(self, view):
        self.height = view.height
        self._row = view.horizon_row()
        self._f = view.camera_matrix[0, 0]

    def horizon_row(self):
        return self._row

    def pixels_per_radian_vertical(self):
        return self._f


def horizon_fit(image, view):
    """Return ``(roll_deg, offset_px, fraction of columns found)`` of the horizon edge."""
    rows = render.horizon_rows(image, _ViewRows(view), search_deg=2.0)
    cols = np.nonzero(np.isfinite(rows))[0]
    if cols.size < 10:
        return math.nan, math.nan, cols.size / image.shape[1]
    slope, intercept = np.polyfit(cols, rows[cols], 1)
    middle = intercept + slope * (view.width - 1) / 2.0
    return math.degrees(math.atan(slope)), middle - view.horizon_row(), cols.size / len(rows)


@pytest.mark.parametrize('mount, roll_deg, pitch_deg, az, el, fov', [
    ('default', 0.0, 0.0, 0.0, 0.0, 60.0), ('default', 4.0, 12.0, 20.0, -4.0, 45.0),
    ('default', -3.0, -8.0, -55.0, 3.0, 90.0), ('tilted', 2.0, 6.0, 38.0, 0.0, 30.0)])
def test_view_matches_the_scenes_own_pinhole_view(scene, mount, roll_deg, pitch_deg, az, el,
                                                  fov):
    """PSNR >= 33 dB over the covered area, shift < 0.3 px, horizon roll <= 0.02 deg."""
    import cv2

    imu_to_camera = DEFAULT_IMU_TO_CAMERA if mount == 'default' else TILTED
    rig = _rig(None if mount == 'default' else TILTED)
    roll, pitch = math.radians(roll_deg), math.radians(pitch_deg)
    mosaic = ViewMosaic(rig)
    for i, image in enumerate(render.render_camera_views(scene, rig, roll, pitch,
                                                         imu_to_camera)):
        mosaic.set_image(i, image)
    pose = ViewPose.from_degrees(az, el, fov)
    view = LevelledView(rig, mosaic.layout, 480, 320, pose, renderer='grid')
    view.set_attitude(roll, pitch)
    # a frame set's first frame: straight from the cameras (view_grid); drawn again: from
    # the undistorted planes (view_warp); both held to the ground truth
    first = view.render(mosaic.image, 1).copy()
    image = view.render(mosaic.image, 1).copy()
    assert view.planes is not None and view.planes.holds(1)
    truth = pinhole_truth(scene, 480, 320, pose, imu_to_camera)
    seen = _seen(view, mosaic)
    assert seen.mean() > 0.3
    assert abs(view.covered_fraction() - seen.mean()) < 0.05
    assert render.psnr(image, truth, seen) >= 33.0
    assert render.psnr(first, truth, seen) >= 33.0
    assert first[view.lookup()[..., 0] == OUTSIDE].max(initial=0) == 0
    # black where no camera sees
    assert image[view.lookup()[..., 0] == OUTSIDE].max(initial=0) == 0
    # shift: phase correlation over the covered area (uncovered set to the truth)
    a = np.where(seen[..., None], image, truth).mean(axis=2).astype(np.float32)
    b = truth.mean(axis=2).astype(np.float32)
    window = cv2.createHanningWindow(a.shape[::-1], cv2.CV_32F)
    (dx, dy), _ = cv2.phaseCorrelate(a, b, window)
    assert math.hypot(dx, dy) < 0.3, (dx, dy)
    a = np.where(seen[..., None], first, truth).mean(axis=2).astype(np.float32)
    (dx, dy), _ = cv2.phaseCorrelate(a, b, window)
    assert math.hypot(dx, dy) < 0.3, ('grid', dx, dy)
    roll_found, offset, found = horizon_fit(image, view)
    if found > 0.5:  # the horizon edge is in the view: level and where K puts it
        assert abs(roll_found) <= 0.02 and abs(offset) < 0.3, (roll_found, offset)


def test_horizon_is_level_across_the_sector_with_a_rolled_and_pitched_rig(scene):
    """Rows parallel to the true horizon at every azimuth, at its predicted row."""
    rig = _rig()
    roll, pitch = math.radians(6.0), math.radians(-9.0)
    mosaic = ViewMosaic(rig)
    for i, image in enumerate(render.render_camera_views(scene, rig, roll, pitch)):
        mosaic.set_image(i, image)
    view = LevelledView(rig, mosaic.layout, 400, 300)
    view.set_attitude(roll, pitch)
    for az in (-70.0, -35.0, 0.0, 35.0, 70.0):
        for el in (-5.0, 4.0):
            view.set_pose(ViewPose.from_degrees(az, el, 50.0))
            roll_found, offset, found = horizon_fit(view.render(mosaic.image), view)
            assert found > 0.8, (az, el)
            assert abs(roll_found) <= 0.02 and abs(offset) < 0.3, (az, el, roll_found, offset)
    # the horizon's row follows elevation: c_y + f tan(el)
    pose = ViewPose.from_degrees(0.0, 5.0, 50.0)
    f = (400 / 2) / math.tan(math.radians(25.0))
    assert horizon_row(300, 400, pose) == pytest.approx(149.5 + f * math.tan(math.radians(5)))


@pytest.mark.parametrize('size, step', [((480, 320), 16), ((333, 211), 16), ((640, 360), 20)])
def test_fast_lookup_matches_exact_within_tolerance(size, step):
    """The panorama's fast builder on a view: within tolerance_px of the exact map."""
    rig = _rig()
    mosaic = ViewMosaic(rig)
    view = LevelledView(rig, mosaic.layout, *size, grid_step=step, tolerance_px=0.1)
    rng = np.random.default_rng(5)
    for k in range(4):
        roll, pitch = rng.uniform(-0.3, 0.3, 2)
        view.set_pose(ViewPose.from_degrees(rng.uniform(-80, 80), rng.uniform(-30, 30),
                                            rng.uniform(10, 120)))
        view.set_attitude(roll, pitch)
        fast = view.lookup()
        exact = view.builder.build_exact(roll, pitch)
        seen = exact[..., 0] != OUTSIDE
        assert np.abs(fast - exact).max(axis=-1)[seen].max() <= 0.1 + 1e-4


def test_lookup_rebuilt_only_when_attitude_or_view_moves():
    """Same attitude and pose: no rebuild; a move past the threshold, or a zoom: rebuild."""
    rig = _rig()
    mosaic = ViewMosaic(rig)
    view = LevelledView(rig, mosaic.layout, 320, 240, rebuild_threshold_deg=0.01)
    view.set_attitude(0.01, 0.02)
    view.render(mosaic.image)
    view.render(mosaic.image)
    assert view.rebuild_count == 1
    view.set_attitude(0.01 + math.radians(0.005), 0.02)
    view.render(mosaic.image)
    assert view.rebuild_count == 1
    view.set_attitude(0.01 + math.radians(0.05), 0.02)
    view.render(mosaic.image)
    assert view.rebuild_count == 2
    view.set_pose(ViewPose.from_degrees(0.0, 0.0, 61.0))
    view.render(mosaic.image)
    assert view.rebuild_count == 3
    view.set_pose(ViewPose.from_degrees(0.0, 0.5, 61.0))
    view.render(mosaic.image)
    assert view.rebuild_count == 4


def test_uncovered_pixels_are_black_and_the_fraction_is_reported(scene):
    """A view looking behind the rig sees nothing: black, covered fraction 0."""
    rig = _rig()
    mosaic = ViewMosaic(rig)
    for i, image in enumerate(render.render_camera_views(scene, rig, 0.0, 0.0)):
        mosaic.set_image(i, image)
    view = LevelledView(rig, mosaic.layout, 320, 240, ViewPose.from_degrees(180.0, 0.0, 40.0))
    view.set_attitude(0.0, 0.0)
    assert view.render(mosaic.image).max() == 0
    assert view.covered_fraction() == 0.0
    view.set_pose(ViewPose.from_degrees(0.0, 0.0, 20.0))
    assert view.covered_fraction() == 1.0
    assert view.render(mosaic.image).min(axis=2).max() > 0


def test_covered_fraction_off_the_grid_map_agrees_with_the_lens(scene):
    """
    The fraction read off a moving view's map is the lens's own, pose by pose.

    A ``'grid'`` view counts the sampled pixels its map sends into a camera's image; a
    ``'warp'`` view (no such map) evaluates the lens at the same pixels. They differ only
    where the map's 0.1 px tolerance crosses a frame's edge.
    """
    rig = _rig()
    mosaic = ViewMosaic(rig)
    for i, image in enumerate(render.render_camera_views(scene, rig, 0.05, 0.2)):
        mosaic.set_image(i, image)
    grid = LevelledView(rig, mosaic.layout, 640, 360, renderer='grid')
    exact = LevelledView(rig, mosaic.layout, 640, 360, renderer='warp')

    def no_lens(*args):
        raise AssertionError('the grid view evaluated the lens for its covered fraction')

    grid.builder.evaluate = no_lens   # read off the map: 0.1-0.3 ms, the lens 1-1.4 ms
    fractions = []
    for k, (az, el, fov) in enumerate([(0, 0, 60), (15, 25, 90), (-40, -35, 120),
                                       (70, 10, 150), (180, 0, 40)]):
        for view in (grid, exact):
            view.set_attitude(0.05, 0.2)
            view.set_pose(ViewPose.from_degrees(az, el, fov))
            view.render(mosaic.image, k)
        assert grid._grid is not None and exact._grid is None
        fractions.append((grid.covered_fraction(), exact.covered_fraction()))
        assert abs(fractions[-1][0] - fractions[-1][1]) <= 0.003, (az, el, fov, fractions)
    assert any(0.05 < f < 0.95 for f, _ in fractions), fractions  # edges were crossed
    assert fractions[-1] == (0.0, 0.0)


@pytest.mark.parametrize('values, reason', [
    ((0.0, 0.0, 0.0), 'fov_h'), ((0.0, 0.0, 180.0), 'fov_h'), ((0.0, 0.0, -10.0), 'fov_h'),
    ((math.nan, 0.0, 60.0), 'finite'), ((0.0, math.inf, 60.0), 'finite'),
    ((0.0, 95.0, 60.0), 'elevation'), (('x', 0.0, 60.0), 'number'),
    ((True, 0.0, 60.0), 'azimuth must be a number'), ((0.0, False, 60.0), 'elevation must be'),
    ((0.0, 0.0, np.True_), 'fov_h must be a number'), ((10 ** 400, 0.0, 60.0), 'finite')])
def test_bad_pose_is_one_clear_reason_and_the_view_keeps_its_state(values, reason):
    """Refuse fov <= 0 or >= 180, NaN or infinite direction: InputError; the last pose stays."""
    rig = _rig()
    view = LevelledView(rig, ViewMosaic(rig).layout, 320, 240,
                        ViewPose.from_degrees(10.0, 2.0, 50.0))
    with pytest.raises(InputError, match=reason):
        view.set_pose(ViewPose.from_degrees(*values))
    assert view.pose.degrees() == pytest.approx((10.0, 2.0, 50.0))
    view.set_attitude(0.1, 0.1)
    with pytest.raises(InputError, match='finite'):
        view.set_attitude(math.nan, 0.0)
    assert view.attitude == (0.1, 0.1)


@pytest.mark.parametrize('value', [True, False, np.True_])
def test_a_boolean_is_not_an_angle(value):
    """``True`` is no 1 rad or 1 deg (a JSON ``true`` turned a browser's view by 1 deg)."""
    with pytest.raises(InputError, match='azimuth must be a number'):
        ViewPose(value, 0.0, 1.0)
    with pytest.raises(InputError, match='elevation must be a number'):
        ViewPose.from_degrees(0.0, value, 60.0)
    rig = _rig()
    view = LevelledView(rig, ViewMosaic(rig).layout, 320, 240)
    view.set_attitude(0.1, 0.1)
    with pytest.raises(InputError, match='pitch must be a number'):
        view.set_attitude(0.0, value)
    assert view.attitude == (0.1, 0.1)


def test_horizon_row_is_none_when_not_in_view():
    """Within the image (pixel edges -0.5..H-0.5) the row; above, below or at +-90 deg None."""
    f = 200 / math.tan(math.radians(30.0))   # a 400x300 view of fov_h 60
    edge = math.degrees(math.atan(150.0 / f))  # the horizon on the top/bottom pixel edge
    for el in (0.0, 10.0, -10.0, edge - 1e-6, -edge + 1e-6):
        row = horizon_row(300, 400, ViewPose.from_degrees(0.0, el, 60.0))
        assert row == pytest.approx(149.5 + f * math.tan(math.radians(el)))
        assert -0.5 <= row <= 299.5
    for el in (edge + 1e-3, -edge - 1e-3, 45.0, -60.0, 89.999, 90.0, -90.0):
        assert horizon_row(300, 400, ViewPose.from_degrees(0.0, el, 60.0)) is None, el
    rig = _rig()
    view = LevelledView(rig, ViewMosaic(rig).layout, 400, 300,
                        ViewPose.from_degrees(0.0, 90.0, 60.0))
    assert view.horizon_row() is None
    view.set_pose(ViewPose.from_degrees(0.0, 0.0, 60.0))
    assert view.horizon_row() == 149.5


@pytest.mark.filterwarnings('error')
@pytest.mark.parametrize('renderer', ['grid', 'warp'])
@pytest.mark.parametrize('size, pose', [((4096, 16), (60.0, 5.0, 170.0)),
                                        ((16, 4096), (20.0, 10.0, 0.5))])
def test_covered_fraction_of_a_very_wide_or_tall_view(scene, monkeypatch, renderer, size,
                                                      pose):
    """
    A 4096 x 16 or 16 x 4096 view: a finite fraction, that of every pixel, no warning.

    The short side was sampled as far apart as the long one (42.7 px): no sample at all,
    so ``nan`` and numpy's "Mean of empty slice" (``accelcal serve`` then sent
    ``"covered": NaN``, not JSON).
    """
    rig = _rig()
    mosaic = ViewMosaic(rig)
    for i, image in enumerate(render.render_camera_views(scene, rig, 0.05, 0.2)):
        mosaic.set_image(i, image)
    fractions = []
    for samples in (view_module.COVERAGE_SAMPLES, max(size)):   # then every pixel
        monkeypatch.setattr(view_module, 'COVERAGE_SAMPLES', samples)
        view = LevelledView(rig, mosaic.layout, *size, ViewPose.from_degrees(*pose),
                            renderer=renderer)
        view.set_attitude(0.05, 0.2)
        if renderer == 'grid':
            view.render(mosaic.image, 1)   # read off the grid map; 'warp': the lens
        fractions.append(view.covered_fraction())
    sampled, every_pixel = fractions
    assert 0.1 < every_pixel < 0.9, fractions   # partly covered: edges are crossed
    assert math.isfinite(sampled) and abs(sampled - every_pixel) < 0.02, fractions


@pytest.mark.parametrize('size', [(0, 240), (320, MAX_VIEW_SIDE_PX + 1), (8, 8), (320.5, 240),
                                  (True, 240)])
def test_view_size_beyond_the_cap_is_refused(size):
    """Sizes outside [16, 4096] px, or not integers, are refused with the cap."""
    rig = _rig()
    with pytest.raises(InputError, match='view (width|height)'):
        LevelledView(rig, ViewMosaic(rig).layout, *size)


def test_azimuth_wraps_and_render_needs_an_attitude():
    """Azimuth 190 deg is -170 deg; rendering before any attitude is a clear error."""
    assert ViewPose.from_degrees(190.0, 0.0, 60.0).degrees()[0] == pytest.approx(-170.0)
    rig = _rig()
    mosaic = ViewMosaic(rig)
    view = LevelledView(rig, mosaic.layout, 320, 240)
    with pytest.raises(InputError, match='attitude'):
        view.render(mosaic.image)
    with pytest.raises(InputError, match='camera 1'):
        mosaic.set_image(1, np.zeros((10, 10), np.uint8))
