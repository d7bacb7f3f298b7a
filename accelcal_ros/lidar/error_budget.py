r"""
Theoretical point error of a LiDAR-INS cloud, paper B eq. (1).

.. math::  \Delta_{cloud} = \sqrt{\Delta_{INS}^2 + \Delta_{GNSS}^2 + \Delta_{LiDAR}^2
           + \Delta_{INS \to LiDAR}^2}

Angular terms (INS attitude, boresight) become metres at the range of interest:
``range * tan(angle)``. Paper B uses 0.1 deg attitude, 1 cm GNSS, 3 cm range and a
boresight of 1 deg before / 0.3 deg after calibration at 100 m, and states the metric
terms as 18 cm, 175 cm and 53 cm, giving 1.76 m and 0.56 m. Exact conversion gives
17.5 cm, 174.5 cm and 52.4 cm and so 1.75 m and 0.55 m: the paper rounded the terms up
before summing. :data:`PAPER_TERMS_M` holds the paper's stated terms; with them
:func:`cloud_error_m` reproduces 1.76 m and 0.56 m exactly (to the centimetre).

The time-synchronisation term (left out of eq. 1 by the paper) is
``v dt + range * omega * dt``; for 10 us, 30 km/h and 180 deg/s at 100 m that is
0.08 mm + 3.1 mm (the paper quotes ~0.5 mm).
"""
import math
from typing import Dict, Tuple

from accelcal_ros.errors import InputError

MAX_ANGLE_DEG = 90.0
"""Angular errors are in [0, 90) deg: at 90 deg the lateral error ``range tan`` is unbounded,
beyond it the tangent turns negative (a 120 deg attitude error read as -173 m at 100 m)."""

PAPER_RANGE_M = 100.0
PAPER_ATTITUDE_DEG = 0.1
PAPER_GNSS_M = 0.01
PAPER_LIDAR_M = 0.03
PAPER_BORESIGHT_BEFORE_DEG = 1.0
PAPER_BORESIGHT_AFTER_DEG = 0.3
PAPER_TERMS_M = {'attitude': 0.18, 'gnss': 0.01, 'lidar': 0.03,
                 'boresight_before': 1.75, 'boresight_after': 0.53}
"""Paper B's metric terms as printed (cm values of the text, in metres)."""


def angle_to_metres(angle_deg: float, range_m: float) -> float:
    """
    Return the lateral error (m) of an angular error ``angle_deg`` at ``range_m``.

    ``angle_deg`` in [0, :data:`MAX_ANGLE_DEG`) (InputError otherwise: the tangent has no
    lateral meaning at or past 90 deg).
    """
    if not 0.0 <= angle_deg < MAX_ANGLE_DEG:
        raise InputError(f'an angular error of {angle_deg:g} deg is outside 0 to '
                         f'{MAX_ANGLE_DEG:g} deg (its lateral error range * tan(angle) is '
                         'unbounded or negative there)')
    return range_m * math.tan(math.radians(angle_deg))


def cloud_error_m(attitude_m: float, gnss_m: float, lidar_m: float, boresight_m: float,
                  sync_m: float = 0.0) -> float:
    """Return paper B eq. (1): the root sum of squares of the metric terms (m)."""
    return math.sqrt(attitude_m ** 2 + gnss_m ** 2 + lidar_m ** 2 + boresight_m ** 2
                     + sync_m ** 2)


def sync_error_m(sync_s: float, speed_m_s: float, rate_deg_s: float, range_m: float) -> float:
    """Return the time-synchronisation error (m): ``v dt + range * omega * dt``."""
    return speed_m_s * sync_s + range_m * math.radians(rate_deg_s) * sync_s


def error_budget(range_m: float = PAPER_RANGE_M, attitude_deg: float = PAPER_ATTITUDE_DEG,
                 gnss_m: float = PAPER_GNSS_M, lidar_m: float = PAPER_LIDAR_M,
                 boresight_deg: float = PAPER_BORESIGHT_AFTER_DEG,
                 sync_m: float = 0.0) -> Dict[str, float]:
    """Return a dict with every term (m) and the total of eq. (1) for angular inputs."""
    terms = {'attitude': angle_to_metres(attitude_deg, range_m), 'gnss': gnss_m,
             'lidar': lidar_m, 'boresight': angle_to_metres(boresight_deg, range_m),
             'sync': sync_m}
    terms['total'] = cloud_error_m(terms['attitude'], gnss_m, lidar_m, terms['boresight'],
                                   sync_m)
    return terms


def paper_totals_m() -> Tuple[float, float]:
    """Return (before, after) calibration totals from the paper's printed terms."""
    t = PAPER_TERMS_M
    before = cloud_error_m(t['attitude'], t['gnss'], t['lidar'], t['boresight_before'])
    after = cloud_error_m(t['attitude'], t['gnss'], t['lidar'], t['boresight_after'])
    return before, after
