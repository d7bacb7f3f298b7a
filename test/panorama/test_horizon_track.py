"""The horizon measured in stitched panoramas, and ``accelcal study motion``'s panorama table."""
import math
import re

from accelcal_ros.cli import main
from accelcal_ros.errors import InputError
from accelcal_ros.panorama.horizon_track import (drive_horizon_errors, edge_rows,
                                                 fit_horizon_tilt, tilt_between_deg)
from accelcal_ros.panorama.projection import PanoramaGeometry
import numpy as np
import pytest


def test_edge_rows_follow_a_blurred_step_exactly():
    """The area method moves exactly with the edge (no pixel-phase ripple), 1/100 px."""
    import cv2

    rows = np.arange(60, dtype=np.float64)[:, None]
    for edge in np.linspace(28.0, 29.0, 11):
        # a step between sky (200) and ground (80), blurred, placed at a fractional row
        profile = 80.0 + 120.0 / (1.0 + np.exp((rows - edge) / 0.6))
        image = np.repeat(profile, 8, axis=1)
        image = cv2.remap(image.astype(np.float32), np.tile(np.arange(8, dtype=np.float32),
                                                            (60, 1)),
                          (rows + 0.37).astype(np.float32).repeat(8, axis=1),
                          cv2.INTER_LINEAR)
        found = edge_rows(image, 29.0, 8, sky_grey=200.0, ground_grey=80.0)
        assert np.allclose(found, edge - 0.37, atol=0.01), (edge, found)
    # a window reaching an uncovered (black) row, or not spanning sky to ground: NaN
    image[2:4] = 0.0
    assert np.isnan(edge_rows(image, 10.0, 8, 200.0, 80.0)).all()
    assert np.isnan(edge_rows(image, 50.0, 5, 200.0, 80.0)).all()


def test_fit_horizon_tilt_needs_enough_columns():
    geometry = PanoramaGeometry(100, 60)
    rows = np.full(100, np.nan)
    rows[40:45] = 29.5
    with pytest.raises(InputError, match='too few to fit'):
        fit_horizon_tilt(rows, geometry)
    with pytest.raises(InputError, match='expected 100 rows'):
        fit_horizon_tilt(rows[:50], geometry)


def test_measured_horizon_error_agrees_with_the_closed_form():
    """
    Known tilt errors: the stitched horizon moves by f * tan(err) within 0.1 px + 2 %.

    f here is the panorama's pixels per radian (137.5); the tolerance covers the
    stitcher's lookup (0.1 px), the measurement (< 0.05 px) and the spherical
    panorama's ``err`` against the perspective ``tan(err)`` (0.3 % at 5 deg).
    """
    true = np.radians([[0.0, 0.0], [2.0, -1.0], [-1.5, 3.0], [1.0, 2.0], [0.5, -0.5]])
    errors = np.radians([[0.0, 0.2], [0.5, 0.0], [1.0, -1.0], [-5.0, 2.0], [0.0, 0.0]])
    result = drive_horizon_errors(true, {'used': true + errors, 'truth': true})
    f = result['px_per_rad']
    assert f == pytest.approx(137.5, abs=0.1)
    aid = result['aids']['used']
    expected = f * np.tan(np.radians(tilt_between_deg(true, true + errors)))
    tolerance = 0.1 + 0.02 * expected
    assert np.all(np.abs(aid['deviation_px'] - expected) <= tolerance), (
        aid['deviation_px'], expected)
    assert np.all(np.abs(aid['tilt_px'] - expected) <= tolerance), (aid['tilt_px'], expected)
    # offset and roll are the two components of the same tilt
    both = np.hypot(aid['offset_px'], f * np.radians(aid['roll_deg']))
    assert np.all(np.abs(both - expected) <= tolerance)
    assert np.all(np.abs(result['aids']['truth']['deviation_px']) < 0.1)
    with pytest.raises(InputError, match='2 frames, the truth has 5'):
        drive_horizon_errors(true, {'short': true[:2]})


def _table(out):
    rows = {}
    for line in out.splitlines():
        m = re.match(r'^(accel only|\+ odometry|\+ gyro|\+ gyro \+ odometry)\s+([\d.]+)\s+'
                     r'([\d.]+)\s+([\d.]+) \|.*\| +([\d.]+)$', line)
        if m:
            rows[m.group(1)] = [float(m.group(k)) for k in (2, 3, 4, 5)]
    return rows


def test_study_motion_reports_the_stitched_horizon_per_aid(capsys):
    """Accelerometer only is far worse than + gyro; each row agrees with its closed form."""
    assert main(['study', 'motion', '--no-anchors', '--panorama-every', '25']) == 0
    out = capsys.readouterr().out
    assert 'Panorama horizon through the drive at 100 Hz (1 fps): 65 frames' in out, out
    rows = _table(out)
    assert set(rows) == {'accel only', '+ odometry', '+ gyro', '+ gyro + odometry'}, out
    for name, (p50, p95, worst, closed_p95) in rows.items():
        assert p50 <= p95 <= worst
        assert p95 == pytest.approx(closed_p95, rel=0.05, abs=0.1), name
    assert rows['accel only'][1] > 10.0 * rows['+ gyro'][1]
    assert rows['+ gyro'][1] < 3.0   # px at 137.5 px/rad: p95 tilt error < 1.25 deg
    assert math.isfinite(rows['+ gyro + odometry'][2])


def test_study_motion_without_the_panorama(capsys):
    assert main(['study', 'motion', '--no-anchors', '--panorama-every', '0']) == 0
    out = capsys.readouterr().out
    assert 'Simulated drive at 100 Hz' in out and 'Panorama horizon' not in out
