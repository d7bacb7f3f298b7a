"""The stitcher's default panorama size: the reference camera's resolution (pure)."""
import math

from accelcal_ros.camera.rig import ring_rig
from accelcal_ros.errors import InputError
from accelcal_ros.panorama.params import (panorama_size, panorama_size_from_focal,
                                          STITCHER_PARAMS)
from accelcal_ros.panorama.projection import PanoramaGeometry
import pytest


@pytest.mark.parametrize('focal_px, fov_h_deg, fov_v_deg', [
    (500.0, 180.0, 120.0), (1000.0, 180.0, 120.0), (550.0, 360.0, 90.0), (37.3, 90.0, 60.0)])
def test_spherical_size_has_the_camera_resolution(focal_px, fov_h_deg, fov_v_deg):
    """One panorama pixel spans 1/f rad (the camera's centre pixel), within the rounding."""
    width, height = panorama_size_from_focal(focal_px, fov_h_deg, fov_v_deg)
    assert width % 2 == 0 and height % 2 == 0
    geometry = PanoramaGeometry(width, height, fov_h_deg, fov_v_deg)
    step_h = geometry.azimuth_rad(1.0) - geometry.azimuth_rad(0.0)
    step_v = geometry.elevation_rad(0.0) - geometry.elevation_rad(1.0)
    for step, side in ((step_h, width), (step_v, height)):
        # rounding to even moves a side by at most 1 px
        assert abs(step * focal_px - 1.0) <= 1.0 / (side - 1) + 1e-12


def test_size_examples_of_the_issue():
    """640x480 cameras with f ~ 500 -> about 1570x1050; 1280x960, f ~ 1000 -> 3150x2100."""
    assert panorama_size_from_focal(500.0, 180.0, 120.0) == (1570, 1048)
    assert panorama_size_from_focal(1000.0, 180.0, 120.0) == (3142, 2094)


def test_cylindrical_height_keeps_f_rows_per_radian_at_the_horizon():
    """Cylindrical rows: 2 f tan(fov_v / 2), so f rows per radian at the horizon."""
    width, height = panorama_size_from_focal(600.0, 180.0, 120.0, 'cylindrical')
    assert height == 2 * round(600.0 * math.tan(math.radians(60.0)))
    geometry = PanoramaGeometry(width, height, 180.0, 120.0, 'cylindrical')
    assert geometry.pixels_per_radian_vertical(0.0) == pytest.approx(600.0, rel=2e-3)


def test_explicit_sides_win_and_zero_means_from_the_rig():
    """width/height > 0 are kept; 0 takes the rule from camera 0's (fx + fy) / 2."""
    rig = ring_rig(3, 640, 480, 550.0, 45.0)
    assert panorama_size(rig, 720, 480, 180.0, 120.0) == (720, 480, None)
    assert panorama_size(rig, 0, 0, 180.0, 120.0) == (1728, 1152, 550.0)
    assert panorama_size(rig, 900, 0, 180.0, 120.0) == (900, 1152, 550.0)


def test_bad_focal_length_is_refused_with_the_reason():
    """A focal length that is not a positive number: InputError naming K."""
    for focal in (0.0, -3.0, float('nan')):
        with pytest.raises(InputError, match='K in the rig file'):
            panorama_size_from_focal(focal, 180.0, 120.0)


def test_size_parameters_default_to_zero_and_refuse_one():
    """The parameters: 0 (from the rig) by default; 1 is refused, 2 accepted."""
    specs = {s.name: s for s in STITCHER_PARAMS}
    for name in ('width', 'height'):
        assert specs[name].default == 0
        assert specs[name].check(0)[1] is None
        assert specs[name].check(2)[1] is None
        assert specs[name].check(1)[1] is not None
