"""The direct renderer's maps (view_grid): every pixel against the exact lens, and its use."""
import math

from accelcal_ros.camera.rig import ring_rig
from accelcal_ros.panorama.mosaic import OUTSIDE
from accelcal_ros.panorama.view import LevelledView, ViewMosaic, ViewPose
import numpy as np
import pytest

LENS = (-0.1, 0.02, 0.0005, -0.0003, 0.0)


@pytest.mark.parametrize('az, el, fov', [(0.0, 0.0, 60.0), (20.0, -4.0, 45.0),
                                         (-55.0, 3.0, 90.0), (10.0, 30.0, 120.0)])
def test_grid_maps_match_the_exact_lens_within_tolerance(az, el, fov):
    """Each camera part's interpolated map is within tolerance_px of the exact lookup."""
    rig = ring_rig(5, 320, 240, 275.0, 36.0, distortion=LENS, mount_error_deg=0.5, seed=2)
    mosaic = ViewMosaic(rig)
    view = LevelledView(rig, mosaic.layout, 480, 320, ViewPose.from_degrees(az, el, fov),
                        renderer='grid')
    view.set_attitude(math.radians(4.0), math.radians(-8.0))
    view.render(mosaic.image, 1)
    grid = view._grid
    assert grid is not None and grid.plan.regions
    exact = view.builder.build_exact(*view.attitude)
    got = grid.map
    ok = exact[..., 0] != OUTSIDE
    assert ok.sum() > 0.3 * 480 * 320
    worst = float(np.abs(got - exact)[ok].max())
    assert worst <= view.tolerance_px, worst
    # where no camera is, the map reads black (outside the mosaic or in a gap) but at
    # a frame's edge (its last half pixel, as the lookup's rule), never a neighbour
    x, y = got[~ok][:, 0], got[~ok][:, 1]
    inside = np.zeros(len(x), bool)
    for (ox, oy), cam in zip(mosaic.layout.offsets, rig.cameras):
        inside |= (x > ox) & (x < ox + cam.width - 1) & (y > oy) & (y < oy + cam.height - 1)
    assert not inside.any(), (x[inside], y[inside])
    assert grid.worst_px <= 0.75 * view.tolerance_px


def test_first_frame_of_a_set_is_drawn_direct_and_again_from_the_planes():
    """A new frame set: the direct maps; the same set again: the shared undistorted planes."""
    rig = ring_rig(5, 320, 240, 275.0, 36.0, distortion=LENS, seed=2)
    mosaic = ViewMosaic(rig)
    rng = np.random.default_rng(4)
    for i in range(len(rig)):
        mosaic.set_image(i, rng.integers(0, 255, (240, 320, 3), dtype=np.uint8))
    view = LevelledView(rig, mosaic.layout, 320, 240, ViewPose.from_degrees(10.0, 0.0, 50.0),
                        renderer='grid')
    view.set_attitude(0.0, 0.0)
    view.render(mosaic.image, mosaic.version)
    assert view.planes is None or not view.planes.holds(mosaic.version)
    view.render(mosaic.image, mosaic.version)
    assert view.planes is not None and view.planes.holds(mosaic.version)
    mosaic.set_image(0, None)
    view.render(mosaic.image, mosaic.version)
    assert not view.planes.holds(mosaic.version)


def test_camera_sources_convert_what_is_asked_once_per_frame_set():
    """Rectangles asked for are right; a second, larger one converts only what is new."""
    import cv2

    from accelcal_ros.panorama.view_grid import CameraSources

    rig = ring_rig(3, 160, 120, 140.0, 36.0, seed=2)
    mosaic = ViewMosaic(rig)
    rng = np.random.default_rng(5)
    for i in range(3):
        mosaic.set_image(i, rng.integers(0, 255, (120, 160, 3), dtype=np.uint8))
    sources = CameraSources(mosaic.layout, [(160, 120)] * 3)
    (x0, y0) = mosaic.layout.offsets[1]
    want = cv2.cvtColor(mosaic.image[y0:y0 + 120, x0:x0 + 160], cv2.COLOR_BGR2BGRA)
    got = sources.get(mosaic.image, 1, (10, 20, 50, 60), mosaic.version)
    assert (got[20:60, 10:50] == want[20:60, 10:50]).all()
    got[:] = 7  # a second ask converts only the strips around (10, 20, 50, 60)
    got = sources.get(mosaic.image, 1, (0, 0, 160, 80), mosaic.version)
    assert (got[0:20, :] == want[0:20, :]).all() and (got[60:80, :] == want[60:80, :]).all()
    assert (got[20:60, 0:10] == want[20:60, 0:10]).all()
    assert (got[20:60, 10:50] == 7).all()
    mosaic.set_image(1, None)  # a new frame set: converted again
    got = sources.get(mosaic.image, 1, (10, 20, 50, 60), mosaic.version)
    assert (got[20:60, 10:50, :3] == 0).all()


def test_grey_views_drawn_direct_match_the_lookup():
    """A grey mosaic: the direct maps give the lookup's image (black where it is)."""
    from accelcal_ros.panorama import render

    rig = ring_rig(5, 320, 240, 275.0, 36.0, distortion=LENS, seed=2)
    scene = render.make_scene(900, 450, seed=3)
    mosaic = ViewMosaic(rig, channels=1)
    for i, image in enumerate(render.render_camera_views(scene, rig, 0.0, 0.0)):
        mosaic.set_image(i, image)
    pose = ViewPose.from_degrees(25.0, 2.0, 70.0)
    grid = LevelledView(rig, mosaic.layout, 320, 200, pose, renderer='grid')
    lookup = LevelledView(rig, mosaic.layout, 320, 200, pose, renderer='map')
    for view in (grid, lookup):
        view.set_attitude(0.02, -0.03)
    a = grid.render(mosaic.image, mosaic.version).astype(float)
    b = lookup.render(mosaic.image, mosaic.version).astype(float)
    assert a.shape == b.shape == (200, 320)
    inside = lookup.lookup()[..., 0] != OUTSIDE
    assert (a[~inside] == 0).all()
    assert np.abs(a - b)[inside].mean() < 1.0 and np.percentile(np.abs(a - b)[inside], 99) < 8
