"""Stitcher against rendered ground truth: PSNR over the covered area, horizon row, edges."""
import math

from accelcal_ros.camera.rig import ring_rig
from accelcal_ros.errors import InputError
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rot_x, rot_z
from accelcal_ros.panorama import render
from accelcal_ros.panorama.projection import PanoramaGeometry
from accelcal_ros.panorama.stitch import Stitcher
import numpy as np
import pytest

LENS = (-0.1, 0.02, 0.0005, -0.0003, 0.0)


@pytest.fixture(scope='module')
def scene():
    """Return the equirectangular texture the views are rendered from (0.2 deg/texel)."""
    return render.make_scene(1800, 900, seed=3)


def _rig(count=5):
    return ring_rig(count, 320, 240, 275.0, 36.0, distortion=LENS, mount_error_deg=0.5, seed=2)


@pytest.mark.parametrize('projection, roll_deg, pitch_deg, mount', [
    ('spherical', 0.0, 0.0, 'default'), ('spherical', 4.0, 12.0, 'default'),
    ('cylindrical', -3.0, -8.0, 'default'), ('spherical', 2.0, 6.0, 'yawed_tilted')])
def test_stitched_panorama_matches_the_scene(scene, projection, roll_deg, pitch_deg, mount):
    """Rendered views stitched with the true attitude reproduce the scene; horizon level."""
    rig = _rig()
    imu_to_camera = DEFAULT_IMU_TO_CAMERA if mount == 'default' else \
        rot_x(math.radians(7.0)) @ DEFAULT_IMU_TO_CAMERA @ rot_z(math.radians(-15.0)).T
    geometry = PanoramaGeometry(720, 480, 180.0, 120.0, projection)
    roll, pitch = math.radians(roll_deg), math.radians(pitch_deg)
    views = render.render_camera_views(scene, rig, roll, pitch, imu_to_camera)
    stitcher = Stitcher(rig, geometry, imu_to_camera)
    panorama = stitcher.stitch(views, roll, pitch)
    truth = render.render_panorama_truth(scene, geometry, imu_to_camera)
    seen = stitcher.coverage()
    assert seen.mean() > 0.2
    assert render.psnr(panorama, truth, seen) > 30.0
    # zero outside every frame
    assert panorama[~seen].max() <= 128 and np.all(panorama[_far_from(seen, 2)] == 0)
    rows = render.horizon_rows(panorama, geometry)
    found = np.isfinite(rows)
    assert found.mean() > 0.9
    # pixel-centre convention: the horizon is at (H-1)/2 = 239.5, not at H/2
    assert np.abs(rows[found] - 239.5).max() < 0.3


def _far_from(mask, distance):
    import cv2

    grown = cv2.dilate(mask.astype(np.uint8), np.ones((2 * distance + 1,) * 2, np.uint8))
    return grown == 0


def test_heading_is_between_the_middle_columns(scene):
    """A post at azimuth 0 is centred on column (W-1)/2 (pixel centres, not corners)."""
    rig = _rig()
    geometry = PanoramaGeometry(720, 480, 180.0, 120.0)
    views = render.render_camera_views(scene, rig, 0.0, 0.0)
    panorama = Stitcher(rig, geometry).stitch(views, 0.0, 0.0).astype(float).mean(axis=2)
    row = int(round(geometry.row_from_elevation(math.radians(9.0))))  # a post, not sky
    darkness = np.clip(120.0 - panorama[row], 0, None)  # the post is dark, the sky bright
    cols = np.arange(340, 380)
    centroid = (cols * darkness[cols]).sum() / darkness[cols].sum()
    assert centroid == pytest.approx(359.5, abs=0.1)


def test_pitch_error_moves_the_horizon_as_predicted(scene):
    """A 2 deg pitch error shifts the horizon by 2 deg at azimuth 0 (8 px at 4 px/deg)."""
    rig = _rig()
    geometry = PanoramaGeometry(720, 480, 180.0, 120.0)
    pitch = math.radians(15.0)
    views = render.render_camera_views(scene, rig, 0.0, pitch)
    panorama = Stitcher(rig, geometry).stitch(views, 0.0, pitch + math.radians(2.0))
    rows = render.horizon_rows(panorama, geometry)
    assert rows[359] - 239.5 == pytest.approx(8.0, abs=0.3)
    assert abs(rows[5] - 239.5) < 1.0  # at azimuth -90 deg a pitch error does not move it


def test_rebuild_threshold_nan_and_render_before_attitude():
    """Small moves reuse the map, large ones rebuild, NaN is rejected keeping the map."""
    stitcher = Stitcher(_rig(3), PanoramaGeometry(360, 240), rebuild_threshold_deg=0.05)
    with pytest.raises(InputError, match='no attitude'):
        stitcher.render()
    assert stitcher.set_attitude(0.0, 0.1)
    assert not stitcher.set_attitude(math.radians(0.03), 0.1)
    assert stitcher.set_attitude(math.radians(0.06), 0.1)
    with pytest.raises(InputError, match='finite'):
        stitcher.set_attitude(float('nan'), 0.1)
    assert stitcher.attitude == (math.radians(0.06), 0.1) and stitcher.rebuild_count == 2


def test_images_are_checked_against_the_rig():
    """Wrong size, type or shape raise errors naming the camera and the expected size."""
    stitcher = Stitcher(_rig(3), PanoramaGeometry(360, 240))
    with pytest.raises(InputError, match=r"camera 1 \('cam1'\).*640x480.*320x240"):
        stitcher.set_image(1, np.zeros((480, 640, 3), np.uint8))
    with pytest.raises(InputError, match='8-bit'):
        stitcher.set_image(0, np.zeros((240, 320, 3), np.uint16))
    with pytest.raises(InputError, match='shape'):
        stitcher.set_image(0, np.zeros((240, 320, 4), np.uint8))
    with pytest.raises(InputError, match='expected 3 images'):
        stitcher.stitch([np.zeros((240, 320), np.uint8)], 0.0, 0.0)


def test_fixed_point_map_gives_the_same_frame_and_stalled_camera_goes_black(scene):
    """Frames on a reused (fixed-point) map match the first; a cleared camera is black."""
    rig = _rig()
    geometry = PanoramaGeometry(720, 480)
    views = render.render_camera_views(scene, rig, 0.0, 0.2)
    stitcher = Stitcher(rig, geometry)
    first = stitcher.stitch(views, 0.0, 0.2)
    second = stitcher.render().copy()
    third = stitcher.render().copy()
    assert np.array_equal(second, third)  # fixed-point map from the second frame on
    # OpenCV's float-map path and its 1/32-pixel fixed-point one differ only at edges
    diff = np.abs(first.astype(int) - second)
    assert diff.max() <= 8 and diff.mean() < 0.05
    builder = stitcher.builder
    exact, labels = builder.build_exact(0.0, 0.2, with_labels=True)
    stitcher.clear_image(1)
    stalled = stitcher.render()
    own = labels == 1
    assert own.sum() > 1000 and stalled[own].max() <= 128
    assert np.array_equal(stalled[_far_from(own, 2)], second[_far_from(own, 2)])


def test_grey_stitcher_and_mixed_inputs(scene):
    """A mono stitcher takes grey images; a colour one expands grey to three channels."""
    rig = _rig(3)
    geometry = PanoramaGeometry(360, 240)
    views = render.render_camera_views(scene, rig, 0.0, 0.0)
    import cv2

    grey = [cv2.cvtColor(v, cv2.COLOR_BGR2GRAY) for v in views]
    mono = Stitcher(rig, geometry, channels=1).stitch(grey, 0.0, 0.0)
    colour = Stitcher(rig, geometry).stitch(grey, 0.0, 0.0)
    assert mono.ndim == 2 and colour.shape == (240, 360, 3)
    assert np.array_equal(colour[..., 0], mono) and np.array_equal(colour[..., 2], mono)


def test_feathered_blending_is_continuous_and_still_faithful(scene):
    """With blending the seams ramp smoothly; on a real scene the PSNR stays high."""
    rig = _rig()
    geometry = PanoramaGeometry(720, 480)
    flat = [np.full((240, 320, 3), 40 * (i + 1), np.uint8) for i in range(5)]
    hard = Stitcher(rig, geometry).stitch(flat, 0.0, 0.0).astype(int)
    soft_stitcher = Stitcher(rig, geometry, blend_width_deg=6.0)
    soft = soft_stitcher.stitch(flat, 0.0, 0.0).astype(int)
    row = 239
    seen = soft_stitcher.coverage()[row]
    jumps_hard = np.abs(np.diff(hard[row, :, 0]))[seen[1:] & seen[:-1]]
    jumps_soft = np.abs(np.diff(soft[row, :, 0]))[seen[1:] & seen[:-1]]
    assert jumps_hard.max() >= 40 and jumps_soft.max() <= 10
    views = render.render_camera_views(scene, rig, 0.05, 0.1)
    blended = soft_stitcher.stitch(views, 0.05, 0.1)
    truth = render.render_panorama_truth(scene, geometry)
    assert render.psnr(blended, truth, soft_stitcher.coverage()) > 30.0


def test_update_copies_during_the_rebuild_and_checks_everything_first(scene):
    """update(): same frame as set_attitude + set_image; bad input changes nothing."""
    rig = _rig()
    geometry = PanoramaGeometry(720, 480)
    views = render.render_camera_views(scene, rig, 0.02, 0.15)
    one_by_one = Stitcher(rig, geometry)
    one_by_one.set_attitude(0.02, 0.15)
    for i, view in enumerate(views):
        one_by_one.set_image(i, view)
    expected = one_by_one.render().copy()
    stitcher = Stitcher(rig, geometry)
    assert stitcher.update(0.02, 0.15, views) is True  # rebuilt, copies in a worker
    assert np.array_equal(stitcher.render(), expected)
    assert stitcher.update(0.02, 0.15, views) is False  # same attitude: copies inline
    builds = stitcher.rebuild_count
    wrong = list(views)
    wrong[3] = views[3][:100]
    with pytest.raises(InputError, match=r"camera 3 \('cam3'\)"):
        stitcher.update(0.3, 0.15, wrong)
    with pytest.raises(InputError, match='finite'):
        stitcher.update(float('nan'), 0.15, views)
    assert stitcher.rebuild_count == builds and stitcher.attitude == (0.02, 0.15)
    assert np.array_equal(stitcher.mosaic, one_by_one.mosaic)
    # None blacks a camera out (a stalled camera), also while rebuilding
    stalled = list(views)
    stalled[1] = None
    stitcher.update(0.03, 0.15, stalled)
    assert not stitcher.mosaic_view(1).any() and stitcher.mosaic_view(0).any()
