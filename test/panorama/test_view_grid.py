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
    got = grid.full_map()
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


def test_grid_maps_over_random_poses_and_sizes():
    """Random poses, attitudes and sizes (odd ones too): every pixel within tolerance."""
    rig = ring_rig(5, 320, 240, 275.0, 36.0, distortion=LENS, mount_error_deg=0.5, seed=3)
    mosaic = ViewMosaic(rig)
    rng = np.random.default_rng(7)
    for _ in range(12):
        width, height = int(rng.integers(40, 300)), int(rng.integers(30, 200))
        pose = ViewPose.from_degrees(rng.uniform(-180, 180), rng.uniform(-40, 40),
                                     rng.uniform(30, 110))
        view = LevelledView(rig, mosaic.layout, width, height, pose, renderer='grid')
        view.set_attitude(rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2))
        view.render(mosaic.image, 1)
        grid = view._grid
        assert grid is not None
        exact = view.builder.build_exact(*view.attitude)
        got = grid.full_map()
        ok = exact[..., 0] != OUTSIDE
        if ok.any():
            assert float(np.abs(got - exact)[ok].max()) <= view.tolerance_px
        x, y = got[~ok][:, 0], got[~ok][:, 1]
        for (ox, oy), cam in zip(mosaic.layout.offsets, rig.cameras):
            assert not ((x > ox) & (x < ox + cam.width - 1) & (y > oy) &
                        (y < oy + cam.height - 1)).any()


def test_regions_are_the_cameras_eq6_pixels():
    """Each region holds exactly the pixels whose eq. 6 camera sees them in its plane."""
    rig = ring_rig(5, 320, 240, 275.0, 36.0, distortion=LENS, mount_error_deg=0.5, seed=3)
    mosaic = ViewMosaic(rig)
    rng = np.random.default_rng(8)
    planes = None
    for _ in range(40):
        width, height = int(rng.integers(16, 260)), int(rng.integers(16, 200))
        pose = ViewPose.from_degrees(rng.uniform(-180, 180), rng.uniform(-90, 90),
                                     rng.uniform(0.5, 170))
        view = LevelledView(rig, mosaic.layout, width, height, pose, planes=planes)
        view.set_attitude(rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5))
        plan = view.plan()
        planes = view.planes
        owner = np.full((height, width), -1)
        for i, (y0, lo, hi) in plan.regions.items():
            for row, (a, b) in enumerate(zip(lo, hi)):
                assert (owner[y0 + row, a:b + 1] == -1).all()
                owner[y0 + row, a:b + 1] = i
        u, v = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
        p = np.stack([u, v, np.ones_like(u)])
        rays = np.einsum('nij,jhw->nihw', plan.rotations, p)  # every camera
        z = rays[:, 2]
        label = z.argmax(axis=0)
        zl = np.take_along_axis(z, label[None], 0)[0]
        xn = np.take_along_axis(rays[:, 0], label[None], 0)[0] / zl
        yn = np.take_along_axis(rays[:, 1], label[None], 0)[0] / zl
        ext = np.asarray(planes.extents)[label]
        want = (zl > 0) & (xn >= ext[..., 0]) & (xn <= ext[..., 1]) & \
            (yn >= ext[..., 2]) & (yn <= ext[..., 3])
        expected = np.where(want, label, -1)
        # pixels within rounding of a boundary may go either way
        second = np.sort(z, axis=0)[-2] if len(z) > 1 else -np.inf
        near = (np.abs(zl - second) < 1e-9 * np.abs(z).max(axis=0)) | (np.abs(zl) < 1e-6)
        for k, (lo_e, hi_e) in enumerate([(0, 1), (2, 3)]):
            q = (xn, yn)[k]
            near |= (np.abs(q - ext[..., lo_e]) < 1e-9) | (np.abs(q - ext[..., hi_e]) < 1e-9)
        assert (owner == expected)[~near].all()


def test_evaluate_takes_a_camera_per_ray():
    """``only`` as an array: each ray through its own camera, as one camera at a time."""
    rig = ring_rig(5, 320, 240, 275.0, 36.0, distortion=LENS, seed=2)
    mosaic = ViewMosaic(rig)
    view = LevelledView(rig, mosaic.layout, 200, 100, ViewPose.from_degrees(20, 5, 60))
    view.set_attitude(0.1, -0.05)
    rotations = view.camera_rotations()
    rng = np.random.default_rng(9)
    rays = np.ascontiguousarray(rng.uniform(-150, 150, (3, 500)).astype(np.float32))
    rays[2] = 1.0
    cams = rng.integers(0, 5, 500)
    label, px, py, side = view.builder._evaluate_soa(rays, rotations, only=cams)
    assert (label == cams).all()
    for i in range(5):
        one = cams == i
        _, qx, qy, qside = view.builder._evaluate_soa(rays[:, one], rotations, only=i)
        assert (qside == side[one]).all()
        ok = (qside & 16) == 0
        np.testing.assert_allclose(px[one][ok], qx[ok], rtol=1e-5, atol=1e-3)
        np.testing.assert_allclose(py[one][ok], qy[ok], rtol=1e-5, atol=1e-3)
    # one camera's rotations with a camera per ray: the same as that camera for all
    _, px, _, side = view.builder._evaluate_soa(rays, rotations[2:3], only=np.zeros(500, int))
    _, qx, _, qside = view.builder._evaluate_soa(rays, rotations[2:3])
    assert (side == qside).all() and (px == qx)[(side & 16) == 0].all()


def test_a_moving_view_hands_no_product_to_a_threaded_blas(monkeypatch):
    """
    The seam cells' product stays in the drawing thread: no ``cv2.gemm`` in a moving frame.

    The seam cells' product by ``cv2.gemm`` went to the OpenCV 5 wheel's threaded
    OpenBLAS, whose second thread then spun on the other core after every call: the
    process took about twice the drawing thread's CPU (16.5-23.4 against 8-11 ms a
    frame, docs/roi.md). Whether that thread spins depends on the machine's load, so the
    call itself is what is checked, over the poses of a moving view with seams (the
    grid's other products are ``np.einsum`` already, ``RigProjection._evaluate_soa``).
    """
    import cv2

    calls = []

    def refuse(*args, **kwargs):
        calls.append('cv2.gemm')   # kept even if a caller swallowed the error
        raise AssertionError('cv2.gemm in a moving frame')

    rig = ring_rig(5, 320, 240, 275.0, 36.0, distortion=LENS, mount_error_deg=0.5, seed=2)
    mosaic = ViewMosaic(rig)
    view = LevelledView(rig, mosaic.layout, 640, 360, ViewPose.from_degrees(0, 0, 60),
                        renderer='grid')
    view.set_attitude(0.03, -0.05)
    monkeypatch.setattr(cv2, 'gemm', refuse)
    seams = 0
    for k in range(12):
        view.set_pose(ViewPose.from_degrees(-40.0 + 7.0 * k, 2.0 * math.sin(k), 60.0))
        view.render(mosaic.image, k)
        seams += len(view._grid.plan.regions) > 1
    assert not calls and seams >= 6, (calls, seams)
