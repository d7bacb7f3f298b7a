r"""
Lens distortion on normalised image coordinates (pure numpy, vectorised).

Normalised coordinates are ``x = X / Z``, ``y = Y / Z`` of a point ``(X, Y, Z)`` in the
camera's optical frame (z forward, x right, y down, REP-103 ``_optical``). Two models,
with the names ROS ``sensor_msgs/CameraInfo`` uses:

- ``plumb_bob`` / ``rational_polynomial``: OpenCV's model (``cv2.projectPoints``),
  coefficients ``[k1, k2, p1, p2, k3]`` or ``[k1, k2, p1, p2, k3, k4, k5, k6]``:

  .. math::
     r^2 = x^2 + y^2,\quad
     s = \frac{1 + k_1 r^2 + k_2 r^4 + k_3 r^6}{1 + k_4 r^2 + k_5 r^4 + k_6 r^6}

     x_d = x s + 2 p_1 x y + p_2 (r^2 + 2 x^2),\quad
     y_d = y s + p_1 (r^2 + 2 y^2) + 2 p_2 x y

- ``equidistant``: OpenCV's fisheye model (``cv2.fisheye``), ``[k1, k2, k3, k4]``:

  .. math::
     \theta = \operatorname{atan}(r),\quad
     \theta_d = \theta (1 + k_1 \theta^2 + k_2 \theta^4 + k_3 \theta^6 + k_4 \theta^8),
     \quad (x_d, y_d) = \frac{\theta_d}{r} (x, y)

The inverses run Newton's method from the distorted point (at most ``iterations``
steps, fewer once every residual is below :data:`CONVERGED`), exact to about 1e-12 for
real lenses within their frame. A distorted point has no real ray where the model gives
none, and the inverses return NaN there rather than a confident wrong answer: where
Newton did not converge (re-distorting the result misses the input by more than
:data:`VALID_RESIDUAL`) or converged past the model's monotonic range (the first
undistorted radius where ``r s(r^2)``, or ``theta_d(theta)``, stops increasing: the
lens folds back there and far-off rays land inside the frame again;
:func:`monotonic_limit2`).
"""
import functools
import math
from typing import Any, Sequence, Tuple, Union

import numpy as np

PLUMB_BOB = 'plumb_bob'
RATIONAL_POLYNOMIAL = 'rational_polynomial'
EQUIDISTANT = 'equidistant'
DISTORTION_MODELS = (PLUMB_BOB, RATIONAL_POLYNOMIAL, EQUIDISTANT)
"""Supported ``distortion_model`` names (ROS ``CameraInfo``)."""
COEFFICIENT_COUNTS = {PLUMB_BOB: 5, RATIONAL_POLYNOMIAL: 8, EQUIDISTANT: 4}
"""Number of coefficients each model stores (shorter OpenCV lists are padded with 0)."""

CONVERGED = 1e-15
"""Newton stops early once every residual (normalised units) is at most this."""
VALID_RESIDUAL = 1e-6
"""Largest re-distortion miss (normalised units, ~1e-3 px) of an undistorted point; more is
a point Newton did not converge on (NaN)."""

Array = np.ndarray
Coefficients = Union[Sequence[Any], np.ndarray]
"""Distortion coefficients: numbers, or arrays broadcasting with the points."""


def distort_normalized(x: Array, y: Array, distortion: Coefficients,
                       model: str = PLUMB_BOB) -> Tuple[Array, Array]:
    """
    Apply the lens model to undistorted normalised coordinates; return ``(xd, yd)``.

    ``distortion`` holds the model's coefficients (numbers, or arrays broadcasting with
    ``x``: one set per point; float32 in gives float32 out). ``plumb_bob`` takes 5
    values, ``rational_polynomial`` 8, ``equidistant`` 4.
    """
    if model == EQUIDISTANT:
        return _distort_equidistant(x, y, distortion)
    if len(distortion) == 8:
        k1, k2, p1, p2, k3, k4, k5, k6 = distortion
        r2 = x * x + y * y
        radial = ((1.0 + r2 * (k1 + r2 * (k2 + r2 * k3)))
                  / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))))
    else:
        k1, k2, p1, p2, k3 = distortion
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xy2 = 2.0 * x * y
    xd = x * radial + p1 * xy2 + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + p2 * xy2
    return xd, yd


def undistort_normalized(xd: Array, yd: Array, distortion: Coefficients,
                         model: str = PLUMB_BOB,
                         iterations: int = 10) -> Tuple[Array, Array]:
    """
    Invert :func:`distort_normalized` by Newton's method (vectorised, float64).

    Returns ``(x, y)`` with ``distort_normalized(x, y) == (xd, yd)`` to about 1e-12 for
    the distortions of real lenses within their frame. Points without a real ray (Newton
    not converged to :data:`VALID_RESIDUAL`, or beyond the monotonic range of the radial
    model, :func:`monotonic_limit2`) give NaN; so does NaN input. For ``equidistant``,
    points at 90 degrees or more off the axis have no normalised coordinates
    (``inf``/NaN); use :func:`undistort_equidistant_angle` there.
    """
    if model == EQUIDISTANT:
        theta, cos_az, sin_az = undistort_equidistant_angle(xd, yd, distortion, iterations)
        radius = np.tan(theta)
        return radius * cos_az, radius * sin_az
    coeffs = tuple(float(v) for v in distortion)
    rational = len(coeffs) == 8
    limit2 = monotonic_limit2(coeffs)
    xd = np.asarray(xd, dtype=float)
    yd = np.asarray(yd, dtype=float)
    if xd.size <= SCALAR_POINTS:  # a few points (P2P's two emitters): plain floats are 10x faster
        pairs = [_newton_point(float(u), float(v), coeffs, rational, iterations, limit2)
                 for u, v in zip(xd.ravel(), yd.ravel())]
        x = np.array([p[0] for p in pairs], dtype=float).reshape(xd.shape)
        y = np.array([p[1] for p in pairs], dtype=float).reshape(yd.shape)
        return x, y
    with np.errstate(all='ignore'):  # unconverged points end as NaN, without warnings
        return _newton(xd, yd, coeffs, rational, iterations, limit2, _largest)


SCALAR_POINTS = 8
"""Up to this many points, :func:`undistort_normalized` iterates on Python floats."""


@functools.lru_cache(maxsize=64)
def monotonic_limit2(coeffs: Tuple[float, ...], model: str = PLUMB_BOB) -> float:
    """
    Return the squared end of the radial model's monotonic range (``inf``: no end).

    For ``plumb_bob``/``rational_polynomial`` (``coeffs`` ``[k1, k2, p1, p2, k3(, k4, k5,
    k6)]``) it is the smallest ``u = r^2 > 0`` (normalised units) where the distorted
    radius ``r s(u)`` stops increasing, ``d(r s)/dr = s + 2 u s'(u) = 0``, or where the
    rational denominator vanishes; for ``equidistant`` (``[k1, k2, k3, k4]``) the smallest
    ``theta^2 > 0`` (rad^2) where ``theta_d'(theta) = 0``. Past it the model folds back
    (a second, false ray per pixel) and the undistortion reports NaN. The tangential
    terms are left out (the radial model's range).
    """
    if model == EQUIDISTANT:
        k1, k2, k3, k4 = coeffs
        return _first_positive_root([1.0, 3.0 * k1, 5.0 * k2, 7.0 * k3, 9.0 * k4])
    k1, k2, _, _, k3 = coeffs[:5]
    slope = [1.0, 3.0 * k1, 5.0 * k2, 7.0 * k3]          # N + 2 u N', lowest power first
    if len(coeffs) != 8 or not any(coeffs[5:]):
        return _first_positive_root(slope)
    k4, k5, k6 = coeffs[5:]
    poly = np.polynomial.polynomial
    numerator = [1.0, k1, k2, k3]
    denominator = [1.0, k4, k5, k6]
    # d(r N/D)/dr = ((N + 2 u N') D - 2 u N D') / D^2
    d_denominator = [k4, 2.0 * k5, 3.0 * k6]
    top = poly.polysub(poly.polymul(slope, denominator),
                       poly.polymul([0.0, 2.0], poly.polymul(numerator, d_denominator)))
    return min(_first_positive_root(list(top)), _first_positive_root(denominator))


def _first_positive_root(coeffs: Sequence[float]) -> float:
    """Smallest real root > 0 of the polynomial ``sum c_i u^i`` (``inf`` if none)."""
    values = [float(c) for c in coeffs]
    while values and values[-1] == 0.0:
        values.pop()
    if len(values) < 2:
        return math.inf
    roots = np.roots(values[::-1])
    real = roots.real[(roots.real > 0.0) & (np.abs(roots.imag) <= 1e-9 * np.abs(roots))]
    return float(real.min()) if real.size else math.inf


def _largest(e: Array) -> float:
    """Return max |e| of an array."""
    return np.abs(e).max()


def _newton_point(xd: float, yd: float, coeffs: Sequence[float], rational: bool,
                  iterations: int, limit2: float) -> Tuple[float, float]:
    """One point on floats; a zero determinant takes the array path (inf/NaN as numpy)."""
    try:
        return _newton(xd, yd, coeffs, rational, iterations, limit2, abs)
    except (ZeroDivisionError, OverflowError):
        with np.errstate(all='ignore'):
            x, y = _newton(np.array([xd]), np.array([yd]), coeffs, rational, iterations,
                           limit2, _largest)
        return float(x[0]), float(y[0])


def _newton(xd: Any, yd: Any, coeffs: Sequence[float], rational: bool, iterations: int,
            limit2: float, largest: Any) -> Tuple[Any, Any]:
    """
    Newton's method on floats or arrays alike; ``largest(e)`` is max |e|.

    Points that miss their input by more than :data:`VALID_RESIDUAL` after ``iterations``
    steps, or end at ``r^2 >= limit2`` (:func:`monotonic_limit2`), come back as NaN.
    """
    k1, k2, p1, p2, k3 = coeffs[:5]
    k4, k5, k6 = coeffs[5:] if rational else (0.0, 0.0, 0.0)
    x, y = xd, yd
    converged = False
    for step in range(iterations + 1):
        r2 = x * x + y * y
        if rational:
            num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
            radial = num / den
        else:
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xy2 = 2.0 * x * y
        ex = x * radial + p1 * xy2 + p2 * (r2 + 2.0 * x * x) - xd
        ey = y * radial + p1 * (r2 + 2.0 * y * y) + p2 * xy2 - yd
        if not getattr(ex, 'size', 1) or max(largest(ex), largest(ey)) <= CONVERGED:
            converged = True
            break
        if step == iterations:  # ex, ey: the residual of the point returned
            break
        if rational:
            d_radial = ((k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)) * den
                        - num * (k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2))) / (den * den)
        else:
            d_radial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
        a = radial + 2.0 * x * x * d_radial + 2.0 * p1 * y + 6.0 * p2 * x
        b = 2.0 * x * y * d_radial + 2.0 * p1 * x + 2.0 * p2 * y
        d = radial + 2.0 * y * y * d_radial + 6.0 * p1 * y + 2.0 * p2 * x
        det = a * d - b * b
        x = x - (d * ex - b * ey) / det
        y = y - (a * ey - b * ex) / det
    if not isinstance(x, np.ndarray):
        if r2 < limit2 and (converged or max(abs(ex), abs(ey)) <= VALID_RESIDUAL):
            return x, y
        return math.nan, math.nan
    bad = ~(r2 < limit2)
    if not converged:
        bad |= ~((np.abs(ex) <= VALID_RESIDUAL) & (np.abs(ey) <= VALID_RESIDUAL))
    if bad.any():
        x = np.where(bad, np.nan, x)
        y = np.where(bad, np.nan, y)
    return x, y


def _distort_equidistant(x: Array, y: Array, distortion: Coefficients) -> Tuple[Array, Array]:
    """Fisheye (``cv2.fisheye``) model of normalised coordinates; see the module text."""
    k1, k2, k3, k4 = distortion
    r = np.sqrt(x * x + y * y)
    theta = np.arctan(r)
    t2 = theta * theta
    theta_d = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
    with np.errstate(divide='ignore', invalid='ignore'):
        scale = np.where(r > 1e-12, theta_d / np.where(r > 1e-12, r, 1.0), 1.0)
    return x * scale, y * scale


def distort_equidistant_angle(theta: Array, distortion: Coefficients) -> Array:
    """Return the fisheye model's distorted radius ``theta_d`` of off-axis angles (rad)."""
    k1, k2, k3, k4 = distortion
    t2 = theta * theta
    return theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))


def undistort_equidistant_angle(xd: Array, yd: Array, distortion: Coefficients,
                                iterations: int = 10) -> Tuple[Array, Array, Array]:
    """
    Return ``(theta, cos_az, sin_az)`` of distorted fisheye coordinates.

    ``theta`` (rad) is the angle off the optical axis (Newton on ``theta_d(theta)``),
    ``cos_az``/``sin_az`` the direction of the point around the axis. ``theta`` is NaN
    where Newton did not converge (residual above :data:`VALID_RESIDUAL`) or past the
    model's monotonic range (:func:`monotonic_limit2`).
    """
    coeffs = tuple(float(v) for v in distortion)
    k1, k2, k3, k4 = coeffs
    limit2 = monotonic_limit2(coeffs, EQUIDISTANT)
    xd = np.asarray(xd, dtype=float)
    yd = np.asarray(yd, dtype=float)
    theta_d = np.hypot(xd, yd)
    theta = theta_d.copy()
    with np.errstate(all='ignore'):
        for step in range(iterations + 1):
            t2 = theta * theta
            value = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - theta_d
            if not value.size or np.abs(value).max() <= CONVERGED or step == iterations:
                break
            slope = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + 9.0 * k4 * t2)))
            theta = theta - value / slope
        bad = ~((np.abs(value) <= VALID_RESIDUAL) & (t2 < limit2))
    if bad.any():
        theta = np.where(bad, np.nan, theta)
    safe = np.where(theta_d > 1e-15, theta_d, 1.0)
    cos_az = np.where(theta_d > 1e-15, xd / safe, 1.0)
    sin_az = np.where(theta_d > 1e-15, yd / safe, 0.0)
    return theta, cos_az, sin_az
