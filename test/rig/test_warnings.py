"""What the calibration warns about: overlapping cameras without shared views."""
from accelcal_ros.frames import rot_y
from accelcal_ros.rig.calibrate import _fov_overlap
import numpy as np


def test_overlap_of_fields_of_view():
    """87 deg cameras 45 deg apart overlap (a pair to share views); 90 deg apart do not."""
    k = np.array([[425.0, 0.0, 399.5], [0.0, 425.0, 299.5], [0.0, 0.0, 1.0]])
    size = (800, 600)
    eye = np.eye(3)
    assert _fov_overlap(k, size, eye, k, size, rot_y(np.radians(45.0)).T)
    assert not _fov_overlap(k, size, rot_y(np.radians(45.0)).T, k, size,
                            rot_y(np.radians(-45.0)).T)
