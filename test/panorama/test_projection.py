"""Panorama pixel <-> ray: the frames contract (pixel centres, horizon row, projections)."""
import math

from accelcal_ros.errors import InputError
from accelcal_ros.panorama.projection import PanoramaGeometry, rays_from_angles
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest


def test_angles_refer_to_pixel_centres():
    """Column 0's centre is half a pixel right of -fov_h/2; the top row's half below +fov_v/2."""
    g = PanoramaGeometry(3600, 2400, 180.0, 120.0)
    step = math.radians(180.0) / 3600
    assert g.azimuth_rad(0) == pytest.approx(-math.pi / 2 + step / 2, abs=1e-12)
    assert g.azimuth_rad(3599) == pytest.approx(math.pi / 2 - step / 2, abs=1e-12)
    assert g.elevation_rad(0) == pytest.approx(math.radians(60) - step / 2, abs=1e-12)
    # Paper A's psi = 0.5 d_alpha (2u/W - 1) is the left edge of pixel u.
    u = np.arange(0, 3600, 7)
    paper = 0.5 * math.pi * (2 * u / 3600 - 1)
    assert np.allclose(g.azimuth_rad(u - 0.5), paper, atol=1e-12)


def test_horizon_and_heading_rows():
    """Elevation 0 is row (H-1)/2 (between the middle rows for even H); azimuth 0 (W-1)/2."""
    for h in (2400, 481):
        g = PanoramaGeometry(720, h, 180.0, 120.0)
        assert g.horizon_row() == (h - 1) / 2
        assert g.elevation_rad(g.horizon_row()) == pytest.approx(0.0, abs=1e-15)
        assert g.row_from_elevation(0.0) == pytest.approx((h - 1) / 2)
    assert PanoramaGeometry(720, 480).column_from_azimuth(0.0) == pytest.approx(359.5)


def test_ray_convention_is_optical_frame():
    """Straight ahead is +z, right is +x, up is -y (optical frame: y down)."""
    assert np.allclose(rays_from_angles(0.0, 0.0), [0, 0, 1])
    assert np.allclose(rays_from_angles(math.pi / 2, 0.0), [1, 0, 0])
    assert np.allclose(rays_from_angles(0.0, math.pi / 2), [0, -1, 0])


@settings(max_examples=60, deadline=None)
@given(st.floats(0, 719), st.floats(0, 479), st.sampled_from(['spherical', 'cylindrical']))
def test_pixel_ray_round_trip(u, v, projection):
    """pixels(rays(u, v)) == (u, v) and the rays are unit vectors."""
    g = PanoramaGeometry(720, 480, 200.0, 110.0, projection)
    ray = g.rays(u, v)
    assert np.linalg.norm(ray) == pytest.approx(1.0)
    back = g.pixels(ray)
    assert back[0] == pytest.approx(u, abs=1e-7)
    assert back[1] == pytest.approx(v, abs=1e-7)


def test_cylindrical_rows_are_equal_height_steps():
    """On the unit cylinder, rows are equal steps of tan(elevation), centred on pixels."""
    g = PanoramaGeometry(100, 200, 90.0, 100.0, 'cylindrical')
    heights = np.tan(g.elevation_rad(np.arange(200)))
    assert np.allclose(np.diff(heights), np.diff(heights)[0])
    top = math.tan(math.radians(50.0))
    assert heights[0] == pytest.approx(top * (1 - 1 / 200))
    assert g.pixels_per_radian_vertical(0.0) == pytest.approx(200 / (2 * top))


@pytest.mark.parametrize('kwargs, words', [
    ({'width': 1}, 'width'), ({'height': 2.5}, 'height'), ({'fov_h_deg': 0.0}, 'fov_h_deg'),
    ({'fov_v_deg': 181.0}, 'fov_v_deg'), ({'fov_v_deg': 175.0, 'projection': 'cylindrical'},
                                          '170'),
    ({'projection': 'fisheye'}, 'projection'), ({'fov_h_deg': float('nan')}, 'fov_h_deg')])
def test_bad_geometry_is_rejected(kwargs, words):
    """Each bad value names itself."""
    with pytest.raises(InputError, match=words):
        PanoramaGeometry(**kwargs)
