r"""
Sensitivity-ellipsoid fit by Levenberg-Marquardt (paper A, eq. 5), in units of g.

For ``K`` still positions with mean raw readings ``a_k`` (g), the corrected specific force
is ``f_k = T diag(1/k) (a_k - b)`` (:mod:`accelcal_ros.sensor.model`), and at rest it
must have unit length. The residual of position ``k`` is paper A's eq. (5),

.. math::  r_k = \lVert T\,\mathrm{diag}(1/k)\,(a_k - b) \rVert - 1,

weighted by its expected standard deviation ``sigma_k`` (noise of the mean reading
projected on the gravity direction), and minimised with scipy's Levenberg-Marquardt
(``least_squares(method='lm')``, MINPACK) with an analytic Jacobian. Models:

* ``diagonal``: paper A's 6 parameters ``w = [k, b]`` (``T = I``);
* ``full``: 9 parameters ``w = [k, b, m]`` with the three imu_tk misalignment angles
  ``m = [m_yz, m_zy, m_zx]`` (rad), which absorb the ~1 % cross-axis coupling of a real
  ADXL345 that the diagonal model cannot.

The parameter covariance is ``s^2 (J_w^T J_w)^{-1}`` with ``J_w`` the weighted Jacobian
and ``s^2 = max(1, chi^2 / (K - p))`` (the known noise, inflated when the residuals show
more than noise). Positions captured while moving are found from their studentized
residual and dropped with a warning; a hold-out check refits without each position (or
each of 5 folds) and reports the residual on the positions left out.
"""
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

from accelcal_ros.calibration.coverage import (describe_direction, direction_spread_deg,
                                               predicted_tilt_error_deg, suggest_directions)
from accelcal_ros.errors import CalibrationError, InputError
from accelcal_ros.sensor.calibration_file import tilt_error_known_deg
from accelcal_ros.sensor.datasheet import NOISE_STD_100HZ_G
from accelcal_ros.sensor.model import MODELS, SensorModel
from accelcal_ros.uncertainty import floor_at_known_error
import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares

"""Calibration models: paper A's 6-parameter one and the 9-parameter imu_tk one."""
PARAMETER_NAMES = {
    'diagonal': ('scale_x', 'scale_y', 'scale_z', 'bias_x', 'bias_y', 'bias_z'),
    'full': ('scale_x', 'scale_y', 'scale_z', 'bias_x', 'bias_y', 'bias_z',
             'misalignment_yz', 'misalignment_zy', 'misalignment_zx'),
}
DEFAULT_NOISE_STD_G = np.array(NOISE_STD_100HZ_G)
"""Per-sample noise (g) assumed when a position has one sample: ADXL345 at 100 Hz."""
NOISE_FLOOR_G = 1e-4
"""Smallest standard deviation (g) trusted for one averaged position (drift, tremor)."""
MAX_CONDITION = 1e3
"""Largest condition number of the column-normalised weighted Jacobian that is accepted."""


def parameter_count(model: str) -> int:
    """Return the number of parameters of ``model`` (6 or 9)."""
    check_model(model)
    return len(PARAMETER_NAMES[model])


def check_model(model: str) -> None:
    """Raise :class:`InputError` unless ``model`` is one of :data:`MODELS`."""
    if model not in MODELS:
        raise InputError(f'unknown calibration model {model!r}; use one of {", ".join(MODELS)}')


def params_to_model(params: ArrayLike, model: str) -> SensorModel:
    """Return the :class:`SensorModel` of a parameter vector ``[k, b(, m)]``."""
    params = np.asarray(params, dtype=float)
    misalignment = params[6:9] if model == 'full' else np.zeros(3)
    return SensorModel(params[0:3], params[3:6], misalignment)


def model_to_params(sensor_model: SensorModel, model: str) -> np.ndarray:
    """Return the parameter vector ``[k, b(, m)]`` of a :class:`SensorModel`."""
    parts = [sensor_model.scale, sensor_model.bias]
    if model == 'full':
        parts.append(sensor_model.misalignment)
    return np.concatenate(parts)


def residuals_and_jacobian(params: np.ndarray, raw_g: np.ndarray,
                           model: str) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return eq. (5) residuals ``r_k`` (K,) and their Jacobian (K, p) at ``params``.

    ``u = (a - b) / k``, ``f = T u``, ``r = |f| - 1``; with ``n = f / |f|``:
    ``dr/dk_i = -(n . T[:, i]) u_i / k_i``, ``dr/db_i = -(n . T[:, i]) / k_i``,
    ``dr/dm_yz = -n_x u_y``, ``dr/dm_zy = n_x u_z``, ``dr/dm_zx = -n_y u_z``.
    """
    params = np.asarray(params, dtype=float)
    scale, bias = params[0:3], params[3:6]
    m_yz, m_zy, m_zx = params[6:9] if model == 'full' else (0.0, 0.0, 0.0)
    t = np.array([[1.0, -m_yz, m_zy], [0.0, 1.0, -m_zx], [0.0, 0.0, 1.0]])
    u = (raw_g - bias) / scale
    f = u @ t.T
    norm = np.linalg.norm(f, axis=1)
    n = f / np.maximum(norm, 1e-12)[:, None]
    nt = n @ t  # (K, 3): n . T[:, i]
    jac = np.empty((len(raw_g), len(params)))
    jac[:, 0:3] = -nt * u / scale
    jac[:, 3:6] = -nt / scale
    if model == 'full':
        jac[:, 6] = -n[:, 0] * u[:, 1]
        jac[:, 7] = n[:, 0] * u[:, 2]
        jac[:, 8] = -n[:, 1] * u[:, 2]
    return norm - 1.0, jac


def position_sigmas_g(raw_g: ArrayLike, std_of_mean_g: ArrayLike) -> np.ndarray:
    """
    Return the expected standard deviation (g) of each position's eq. (5) residual.

    The noise of a mean reading, ``std_of_mean_g`` (K, 3) per axis, projected on the
    direction of that reading (the residual is the reading's length), floored at
    :data:`NOISE_FLOOR_G`.
    """
    direction = raw_g / np.linalg.norm(raw_g, axis=1)[:, None]
    std = np.maximum(np.asarray(std_of_mean_g, dtype=float), NOISE_FLOOR_G)
    return np.sqrt(np.sum((direction * std) ** 2, axis=1))


@dataclass
class FitResult:
    """Outcome of :func:`fit_ellipsoid`; every vector in g, angles in rad."""

    model: str
    sensor_model: SensorModel
    parameters: np.ndarray
    covariance: np.ndarray
    residuals_g: np.ndarray
    """Eq. (5) residual of every captured position (also the dropped ones)."""
    used: np.ndarray
    """Boolean mask: positions kept in the final fit."""
    captures_g: np.ndarray
    """Mean raw reading (g) of every captured position, (K, 3)."""
    residual_rms_g: float
    holdout_rms_g: Optional[float]
    condition_number: float
    predicted_tilt_error_deg: float
    evaluations: int
    warnings: List[str] = field(default_factory=list)

    @property
    def positions(self) -> int:
        """Return the number of positions used in the fit."""
        return int(np.count_nonzero(self.used))

    @property
    def dropped(self) -> List[int]:
        """Return the indices of the positions dropped as outliers."""
        return [int(i) for i in np.flatnonzero(~self.used)]

    @property
    def std(self) -> np.ndarray:
        """Return the standard deviation of each parameter (same order as ``parameters``)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def scale_std(self) -> np.ndarray:
        """Return the standard deviations of the scale factors."""
        return self.std[0:3]

    @property
    def bias_std(self) -> np.ndarray:
        """Return the standard deviations of the biases (g)."""
        return self.std[3:6]

    @property
    def misalignment_std(self) -> np.ndarray:
        """Return the standard deviations of the misalignment angles (rad; 0 if diagonal)."""
        return self.std[6:9] if self.model == 'full' else np.zeros(3)

    def summary(self) -> str:
        """Return a one-line human summary of the fit."""
        holdout = ('n/a' if self.holdout_rms_g is None
                   else f'{self.holdout_rms_g * 1e3:.2f} mg')
        text = (f'{self.model} model from {self.positions} positions: residual RMS '
                f'{self.residual_rms_g * 1e3:.2f} mg, hold-out {holdout}, predicted '
                f'roll/pitch error (p95) {self.predicted_tilt_error_deg:.3f} deg')
        if self.dropped:
            text += f'; dropped position(s) {self.dropped}'
        return text


def _solve(raw_g, sigmas, model, initial):
    def fun(p):
        return residuals_and_jacobian(p, raw_g, model)[0] / sigmas

    def jac(p):
        return residuals_and_jacobian(p, raw_g, model)[1] / sigmas[:, None]

    return least_squares(fun, initial, jac=jac, method='lm', x_scale='jac',
                         xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=2000)


def _covariance(params, raw_g, sigmas, model):
    residuals, jac = residuals_and_jacobian(params, raw_g, model)
    weighted = jac / sigmas[:, None]
    dof = len(raw_g) - len(params)
    chi2 = float(np.sum((residuals / sigmas) ** 2))
    inflation = max(1.0, chi2 / dof) if dof > 0 else 1.0
    info = weighted.T @ weighted
    return np.linalg.pinv(info) * inflation, weighted, residuals


def condition_number(weighted_jacobian: ArrayLike) -> float:
    """Return the condition number of a Jacobian with its columns scaled to unit length."""
    norms = np.linalg.norm(weighted_jacobian, axis=0)
    if np.any(norms == 0.0):
        return float('inf')
    singular = np.linalg.svd(weighted_jacobian / norms, compute_uv=False)
    return float(singular[0] / singular[-1]) if singular[-1] > 0 else float('inf')


def _refusal_hint(raw_g, model):
    spread, axis = direction_spread_deg(raw_g)
    hints = suggest_directions(raw_g, count=3)
    where = (f'all positions lie within {spread:.0f} deg of "{describe_direction(axis)}"'
             if spread < 90.0 else 'they do not span the sphere well enough')
    return where, '; '.join(hints)


def fit_ellipsoid(raw_g: ArrayLike, std_of_mean_g: Optional[ArrayLike] = None,
                  samples_per_position: Optional[int] = None, model: str = 'full',
                  initial: Optional[SensorModel] = None, drop_outliers: bool = True,
                  outlier_threshold: float = 6.0, holdout: bool = True,
                  min_positions: Optional[int] = None, max_condition: float = MAX_CONDITION,
                  max_predicted_deg: float = 5.0) -> 'FitResult':
    """
    Fit the sensitivity ellipsoid to ``K`` mean still readings ``raw_g`` (K, 3), in g.

    ``std_of_mean_g`` (K, 3) is each position's noise of the mean (sample std / sqrt(N));
    if not given, :data:`DEFAULT_NOISE_STD_G` / sqrt(``samples_per_position`` or 1) is
    assumed. ``min_positions`` defaults to the parameter count + 1. Returns a
    :class:`FitResult`. Raises :class:`InputError` for NaN/wrong-shaped input and
    :class:`CalibrationError` (with what to do) for too few or badly spread positions.
    """
    check_model(model)
    raw_g = np.asarray(raw_g, dtype=float)
    if raw_g.ndim != 2 or raw_g.shape[1] != 3:
        raise InputError(f'expected mean readings of shape (K, 3), got {raw_g.shape}')
    if not np.all(np.isfinite(raw_g)):
        raise InputError('mean readings contain NaN or infinity; drop those positions')
    count = parameter_count(model)
    needed = count + 1 if min_positions is None else max(int(min_positions), count)
    if len(raw_g) < needed:
        raise CalibrationError(
            f'{len(raw_g)} positions are too few for the {model} model ({count} parameters): '
            f'capture at least {needed}, well spread over the sphere (e.g. the 6 faces of a '
            'box plus 6 edges or corners)')
    if std_of_mean_g is None:
        per_sample = 1 if samples_per_position is None else max(int(samples_per_position), 1)
        std_of_mean_g = np.tile(DEFAULT_NOISE_STD_G / np.sqrt(per_sample), (len(raw_g), 1))
    std_of_mean_g = np.asarray(std_of_mean_g, dtype=float).reshape(len(raw_g), 3)
    std_of_mean_g = np.where(np.isfinite(std_of_mean_g), std_of_mean_g, DEFAULT_NOISE_STD_G)
    sigmas = position_sigmas_g(raw_g, std_of_mean_g)
    start = (np.concatenate([np.ones(3), np.zeros(3 if model == 'diagonal' else 6)])
             if initial is None else model_to_params(initial, model))

    # Conditioning at the start point: refuse before iterating on a hopeless set.
    _, jac0 = residuals_and_jacobian(start, raw_g, model)
    cond0 = condition_number(jac0 / sigmas[:, None])
    if not np.isfinite(cond0) or cond0 > max_condition:
        where, hints = _refusal_hint(raw_g, model)
        raise CalibrationError(
            f'the {len(raw_g)} positions do not constrain the {model} model '
            f'(condition number {cond0:.3g} > {max_condition:.0g}): {where}. '
            f'Add positions with the sensor turned over and on its sides, e.g. {hints}')

    used = np.ones(len(raw_g), dtype=bool)
    warnings = []
    max_drops = max(1, (len(raw_g) - count) // 3)
    while True:
        solution = _solve(raw_g[used], sigmas[used], model, start)
        params = solution.x
        if np.any(params[0:3] <= 0.0) or not np.all(np.isfinite(params)):
            raise CalibrationError('the fit did not converge to a positive scale; check that '
                                   'the readings are in g and the positions are still')
        cov, weighted, _ = _covariance(params, raw_g[used], sigmas[used], model)
        if not drop_outliers or np.count_nonzero(used) - count < 3 \
                or np.count_nonzero(~used) >= max_drops:
            break
        worst, score, residual = _worst_position(params, raw_g[used], sigmas[used], model,
                                                 weighted)
        if score <= outlier_threshold:
            break
        index = int(np.flatnonzero(used)[worst])
        used[index] = False
        warnings.append(
            f'position {index} dropped: residual {abs(residual) * 1e3:.2f} mg is '
            f'{score:.0f} times what the noise explains (was the sensor moving?)')
        start = params

    residuals_all = residuals_and_jacobian(params, raw_g, model)[0]
    cond = condition_number(weighted)
    if cond > max_condition:
        where, hints = _refusal_hint(raw_g[used], model)
        raise CalibrationError(
            f'the positions do not constrain the {model} model (condition number '
            f'{cond:.3g}): {where}. Add positions, e.g. {hints}')
    holdout_rms = _holdout_rms(raw_g[used], sigmas[used], model, params) if holdout else None
    if len(raw_g[used]) < count + 3:
        warnings.append(f'only {len(raw_g[used])} positions for {count} parameters: '
                        'outliers cannot be checked; capture a few more')
    sensor_model = params_to_model(params, model)
    predicted = predicted_tilt_error_deg(sensor_model, cov, model)
    if predicted > max_predicted_deg:
        where, hints = _refusal_hint(raw_g[used], model)
        raise CalibrationError(
            f'the positions constrain the {model} model too weakly (predicted roll/pitch '
            f'error {predicted:.1f} deg): {where}. Add positions, e.g. {hints}')
    predicted, note = floor_at_known_error(
        predicted, tilt_error_known_deg(holdout_rms, float(np.sqrt(np.mean(
            residuals_all[used] ** 2)))), ' deg', 'predicted roll/pitch error')
    if note:
        warnings.append(note)
    if predicted > 0.5:
        warnings.append(f'predicted roll/pitch error {predicted:.2f} deg is large: add '
                        'positions, e.g. ' + '; '.join(suggest_directions(raw_g[used], 3)))
    return FitResult(
        model=model, sensor_model=sensor_model, parameters=params, covariance=cov,
        residuals_g=residuals_all, used=used, captures_g=raw_g,
        residual_rms_g=float(np.sqrt(np.mean(residuals_all[used] ** 2))),
        holdout_rms_g=holdout_rms, condition_number=cond,
        predicted_tilt_error_deg=predicted, evaluations=int(solution.nfev),
        warnings=warnings)


def _worst_position(params, raw_g, sigmas, model, weighted):
    """
    Return ``(index, score, residual_g)`` of the position most unlike the others.

    Up to 40 positions: each is left out in turn, the rest refitted, and its deletion
    residual divided by its predicted standard deviation and by the refit's
    ``sqrt(max(1, chi^2/dof))`` (so a model error that affects every position scores
    low). More positions: studentized residuals ``r_k / (sigma_k sqrt(1 - h_k))`` over
    their median.
    """
    count = len(raw_g)
    if count > 40:
        hat = np.einsum('ij,jk,ik->i', weighted, np.linalg.pinv(weighted.T @ weighted),
                        weighted)
        residuals = residuals_and_jacobian(params, raw_g, model)[0]
        student = np.abs(residuals / sigmas) / np.sqrt(np.clip(1.0 - hat, 1e-3, None))
        worst = int(np.argmax(student))
        score = student[worst] / max(1.0, float(np.median(student)) / 0.6745)
        return worst, float(score), float(residuals[worst])
    best = (0, 0.0, 0.0)
    for k in range(count):
        keep = np.arange(count) != k
        solution = _solve(raw_g[keep], sigmas[keep], model, params)
        res_rest, jac_rest = residuals_and_jacobian(solution.x, raw_g[keep], model)
        dof = count - 1 - len(params)
        chi2 = float(np.sum((res_rest / sigmas[keep]) ** 2))
        scale = np.sqrt(max(1.0, chi2 / dof)) if dof > 0 else 1.0
        w_rest = jac_rest / sigmas[keep][:, None]
        res_k, jac_k = residuals_and_jacobian(solution.x, raw_g[k:k + 1], model)
        w_k = jac_k[0] / sigmas[k]
        leverage = float(w_k @ np.linalg.pinv(w_rest.T @ w_rest) @ w_k)
        score = abs(res_k[0] / sigmas[k]) / np.sqrt(1.0 + leverage) / scale
        if score > best[1]:
            best = (k, float(score), float(res_k[0]))
    return best


def _holdout_rms(raw_g, sigmas, model, params):
    """RMS eq. (5) residual of positions left out of the fit (leave-one-out or 5-fold)."""
    count = len(raw_g)
    folds = count if count <= 20 else 5
    if count - int(np.ceil(count / folds)) < len(params) + 1:
        return None
    left_out = []
    for fold in range(folds):
        test = (np.arange(count) % folds) == fold
        try:
            solution = _solve(raw_g[~test], sigmas[~test], model, params)
        except (ValueError, np.linalg.LinAlgError):
            return None
        left_out.append(residuals_and_jacobian(solution.x, raw_g[test], model)[0])
    return float(np.sqrt(np.mean(np.concatenate(left_out) ** 2)))
