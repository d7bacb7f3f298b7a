r"""
How well a set of calibration positions covers the sphere, and what error it predicts.

Directions are those of the specific force ``f`` in the sensor frame (REP-145: the axis
pointing up reads +1 g), so "+z up" is the sensor lying level and "-z up" upside down.

* :func:`coverage_fraction`: share of all orientations that lie within ``radius_deg``
  of a captured one (40 deg: 12 well spread positions cover 100 %).
* :func:`predicted_tilt_error_deg`: the 95th percentile of the roll and pitch errors
  over :data:`TEST_GRID` that the fit's parameter covariance predicts (Monte Carlo over
  the covariance, the fitted model standing in for the truth) -- the same statistic the
  accuracy study measures against ground truth.
* :func:`suggest_directions`: which of 26 easy orientations (box faces, edges, corners)
  to add, greedily farthest from what was captured.
* :func:`recommended_directions`: the fixed layouts the documentation recommends.
"""
import itertools
from typing import List, Sequence, Tuple, Union

from accelcal_ros.frames import roll_pitch_from_specific_force, specific_force_from_roll_pitch
from accelcal_ros.sensor.model import SensorModel
import numpy as np
from numpy.typing import ArrayLike


def _grid():
    roll = np.radians(np.arange(-180.0, 180.0, 30.0))
    pitch = np.radians(np.arange(-75.0, 76.0, 15.0))
    rr, pp = np.meshgrid(roll, pitch, indexing='ij')
    return np.stack([rr.ravel(), pp.ravel()], axis=1)


TEST_GRID = _grid()
"""Test orientations (roll, pitch) in rad: roll -180..150 step 30, pitch -75..75 step 15."""


def _candidates():
    out = []
    for combo in itertools.product((-1, 0, 1), repeat=3):
        if any(combo):
            vector = np.array(combo, dtype=float)
            out.append(vector / np.linalg.norm(vector))
    return np.array(out)


CANDIDATES = _candidates()
"""The 26 easy orientations: 6 faces, 12 edges and 8 corners of a box (unit ``f``)."""


def unit_directions(vectors: ArrayLike) -> np.ndarray:
    """Return the rows of ``vectors`` (N, 3) scaled to unit length."""
    vectors = np.asarray(vectors, dtype=float).reshape(-1, 3)
    return vectors / np.maximum(np.linalg.norm(vectors, axis=1), 1e-12)[:, None]


def fibonacci_directions(count: int) -> np.ndarray:
    """Return ``count`` near-uniform unit directions (Fibonacci sphere), (count, 3)."""
    k = np.arange(count) + 0.5
    z = 1.0 - 2.0 * k / count
    azimuth = np.pi * (1.0 + 5.0 ** 0.5) * k
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(azimuth), r * np.sin(azimuth), z], axis=1)


_COVERAGE_PROBES = fibonacci_directions(600)


def coverage_fraction(directions: ArrayLike, radius_deg: float = 40.0) -> float:
    """Return the share (0..1) of the sphere within ``radius_deg`` of any direction given."""
    directions = unit_directions(directions)
    if len(directions) == 0:
        return 0.0
    closest = np.max(_COVERAGE_PROBES @ directions.T, axis=1)
    return float(np.mean(closest >= np.cos(np.radians(radius_deg))))


def direction_spread_deg(directions: ArrayLike) -> Tuple[float, np.ndarray]:
    """Return ``(largest angle from the mean direction in deg, mean direction)``."""
    directions = unit_directions(directions)
    mean = directions.sum(axis=0)
    norm = np.linalg.norm(mean)
    if norm < 1e-9:
        return 180.0, np.array([0.0, 0.0, 1.0])
    axis = mean / norm
    spread = np.degrees(np.arccos(np.clip(directions @ axis, -1.0, 1.0))).max()
    return float(spread), axis


def describe_direction(direction: ArrayLike) -> str:
    """
    Name an orientation by its up-pointing axes and roll/pitch, e.g. ``+x-z up (r 180, p -45)``.

    The name is that of the nearest of the 26 :data:`CANDIDATES`; roll and pitch (deg,
    REP-103) are those of ``direction`` itself.
    """
    d = unit_directions(direction)[0]
    nearest = CANDIDATES[int(np.argmax(CANDIDATES @ d))]
    axes = ''.join(f'{"+" if v > 0 else "-"}{name}'
                   for v, name in zip(nearest, 'xyz') if abs(v) > 1e-9)
    roll, pitch = roll_pitch_from_specific_force(d)
    label = {'+z': ' (level)', '-z': ' (upside down)'}.get(axes, '')
    roll_deg, pitch_deg = (int(round(float(np.degrees(v)))) + 0 for v in (roll, pitch))
    return f'{axes} up{label} (roll {roll_deg}, pitch {pitch_deg} deg)'


def suggest_directions(captured: ArrayLike, count: int = 3,
                       min_separation_deg: float = 25.0) -> List[str]:
    """
    Return names of up to ``count`` easy orientations to add, farthest from those captured.

    Greedy farthest-point choice among :data:`CANDIDATES`; candidates within
    ``min_separation_deg`` of a captured or chosen direction are never suggested.
    """
    return [name for name, _ in suggested_directions(captured, count, min_separation_deg)]


def missing_directions(captured: ArrayLike, radius_deg: float = 40.0,
                       layout: int = 12) -> np.ndarray:
    """Directions of :func:`recommended_directions` (``layout``) not yet within ``radius_deg``."""
    wanted = recommended_directions(layout)
    captured = unit_directions(captured) if np.size(captured) else np.zeros((0, 3))
    if not len(captured):
        return wanted
    closest = np.max(wanted @ captured.T, axis=1)
    return wanted[closest < np.cos(np.radians(radius_deg))]


def suggested_directions(captured: ArrayLike, count: int = 3, min_separation_deg: float = 25.0
                         ) -> List[Tuple[str, np.ndarray]]:
    """:func:`suggest_directions` with each suggestion's unit ``f`` direction."""
    captured = np.asarray(captured, dtype=float).reshape(-1, 3)
    chosen = list(unit_directions(captured)) if len(captured) else []
    names: List[Tuple[str, np.ndarray]] = []
    for _ in range(count):
        if chosen:
            closest = np.max(CANDIDATES @ np.array(chosen).T, axis=1)
        else:
            closest = -CANDIDATES[:, 2]  # nothing yet: start level
        best = int(np.argmin(closest))
        if chosen and closest[best] > np.cos(np.radians(min_separation_deg)):
            break
        chosen.append(CANDIDATES[best])
        names.append((describe_direction(CANDIDATES[best]), CANDIDATES[best].copy()))
    return names


def tilt_errors_rad(truth: SensorModel,
                    estimates: Union[Sequence[SensorModel], Tuple[np.ndarray, ...]],
                    grid: ArrayLike = TEST_GRID) -> Tuple[np.ndarray, np.ndarray]:
    """
    Roll and pitch errors (rad) of calibrations over the test orientations.

    ``truth`` is a :class:`~accelcal_ros.sensor.model.SensorModel` that makes the raw
    readings (noise-free); ``estimates`` a list of them (or arrays of scale (S, 3), bias
    (S, 3), misalignment (S, 3)) that correct them. Returns ``(roll_err, pitch_err)``,
    each (S, G), roll wrapped to [-pi, pi).
    """
    if isinstance(estimates, tuple):
        scale, bias, mis = (np.asarray(a, dtype=float) for a in estimates)
    else:
        scale = np.array([e.scale for e in estimates])
        bias = np.array([e.bias for e in estimates])
        mis = np.array([e.misalignment for e in estimates])
    grid = np.asarray(grid, dtype=float)
    force = specific_force_from_roll_pitch(grid[:, 0], grid[:, 1])
    raw = truth.distort(force)  # (G, 3)
    m_yz, m_zy, m_zx = mis[:, 0], mis[:, 1], mis[:, 2]
    u = (raw[None, :, :] - bias[:, None, :]) / scale[:, None, :]  # (S, G, 3)
    f = np.empty_like(u)
    f[..., 0] = u[..., 0] - m_yz[:, None] * u[..., 1] + m_zy[:, None] * u[..., 2]
    f[..., 1] = u[..., 1] - m_zx[:, None] * u[..., 2]
    f[..., 2] = u[..., 2]
    roll, pitch = roll_pitch_from_specific_force(f)
    roll_err = np.mod(roll - grid[None, :, 0] + np.pi, 2.0 * np.pi) - np.pi
    return roll_err, pitch - grid[None, :, 1]


def predicted_tilt_error_deg(sensor_model: SensorModel, covariance: ArrayLike, model: str,
                             samples: int = 300, seed: int = 0) -> float:
    """
    Return the predicted p95 roll/pitch error (deg) of a fit, from its covariance.

    Draws ``samples`` parameter vectors from ``N(fit, covariance)`` (fixed seed: the
    prediction is deterministic), treats the fitted model as the truth and pools the
    absolute roll and pitch errors over :data:`TEST_GRID`.
    """
    params = np.concatenate([sensor_model.scale, sensor_model.bias]
                            + ([sensor_model.misalignment] if model == 'full' else []))
    covariance = np.asarray(covariance, dtype=float)
    if not np.all(np.isfinite(covariance)):
        return float('inf')
    rng = np.random.default_rng(seed)
    draws = rng.multivariate_normal(params, covariance, size=samples, method='svd')
    mis = draws[:, 6:9] if model == 'full' else np.zeros((samples, 3))
    scale = np.maximum(draws[:, 0:3], 1e-6)
    roll_err, pitch_err = tilt_errors_rad(sensor_model, (scale, draws[:, 3:6], mis))
    pooled = np.abs(np.concatenate([roll_err.ravel(), pitch_err.ravel()]))
    return float(np.degrees(np.percentile(pooled, 95.0)))


def recommended_directions(count: int = 12) -> np.ndarray:
    """
    Return the recommended layout of ``count`` positions as unit ``f`` directions.

    ``count = 6``: the six box faces. ``count = 12``: the vertices of a regular
    icosahedron (the most uniform 12 directions), oriented so that every one is an easy
    hold: roll +-31.7 / +-148.3 deg at pitch 0, roll +-90 deg at pitch +-31.7 deg, roll
    0 / 180 deg at pitch +-58.3 deg. ``count = 14``: the six faces and eight corners of a
    box. Other counts: a Fibonacci sphere.
    """
    if count == 6:
        return np.vstack([np.eye(3), -np.eye(3)])
    if count == 12:
        golden = (1.0 + 5.0 ** 0.5) / 2.0
        vertices = []
        for a, b in itertools.product((-1.0, 1.0), repeat=2):
            vertices += [(0.0, a, b * golden), (a, b * golden, 0.0), (b * golden, 0.0, a)]
        return unit_directions(vertices)
    if count == 14:
        corners = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))
        return np.vstack([np.eye(3), -np.eye(3), unit_directions(corners)])
    return fibonacci_directions(count)


def roll_pitch_deg_of(directions: ArrayLike) -> np.ndarray:
    """Return (roll, pitch) in degrees of unit specific-force directions, (N, 2)."""
    roll, pitch = roll_pitch_from_specific_force(unit_directions(directions))
    return np.degrees(np.stack([roll, pitch], axis=1))


__all__ = ['TEST_GRID', 'CANDIDATES', 'coverage_fraction', 'describe_direction',
           'direction_spread_deg', 'suggest_directions', 'tilt_errors_rad',
           'predicted_tilt_error_deg', 'recommended_directions', 'roll_pitch_deg_of',
           'fibonacci_directions', 'unit_directions']
