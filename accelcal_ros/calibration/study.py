r"""
Accuracy study of the field calibration against ground truth (``accelcal study calibration``).

Monte Carlo on the simulated ADXL345 (:mod:`accelcal_ros.driver.sim_sensor`): truth =
paper A's K = 500 estimates (``paper_a_model(500)``), datasheet noise at 100 Hz (2.9 / 2.9 /
4.3 mg), 3.9 mg quantisation. For each number of positions K, layout (uniform random
directions as in paper A, or the recommended fixed set of
:func:`~accelcal_ros.calibration.coverage.recommended_directions`) and sampling (one sample
or 1 s = 100 samples averaged per position), ``trials`` calibrations are fitted by the
package's own LM fit and compared with the truth: parameter errors, RMS distance of
corrected readings from the unit sphere, and roll/pitch errors over
:data:`~accelcal_ros.calibration.coverage.TEST_GRID` (mean, p95, max).

Also: paper A's worked example (Table 1's K = 100 and K = 300 sets applied to a level
sensor) recomputed with the package's own model and angle code, see
:func:`paper_worked_example`.
"""
import time
from typing import Callable, List, Optional, Sequence, Tuple

from accelcal_ros.calibration.coverage import (recommended_directions, TEST_GRID, tilt_errors_rad,
                                               unit_directions)
from accelcal_ros.calibration.ellipsoid_fit import fit_ellipsoid, parameter_count
from accelcal_ros.errors import CalibrationError, InputError
from accelcal_ros.frames import (paper_roll_pitch, roll_pitch_from_specific_force,
                                 specific_force_from_roll_pitch)
from accelcal_ros.recording.progress import Progress
from accelcal_ros.sensor.datasheet import datasheet_noise_std_g, FULL_RES_G_PER_LSB
from accelcal_ros.sensor.model import paper_a_model, SensorModel
import numpy as np

SIM_RATE_HZ = 100.0
"""Sampling rate of the simulated captures: 1 s per position = 100 samples."""
POSITION_COUNTS = (6, 9, 12, 24, 100, 300, 500)
REAL_LIKE_MISALIGNMENT = (0.008, -0.006, 0.01)
"""A real ADXL345's ~1 % cross-axis coupling as misalignment angles (rad), for the study."""
PAPER_LEVEL_VECTORS = {100: (-0.062, -0.0076, -1.071), 300: (-0.029, -0.058, -1.09)}
"""Paper A's corrected level readings (its sign convention: level reads [0, 0, -1])."""
PAPER_PITCH_ERRORS_DEG = {100: 3.31, 300: 1.53}


def layout_directions(layout: str, positions: int, rng: np.random.Generator) -> np.ndarray:
    """Return unit ``f`` directions (positions, 3): ``recommended`` or ``random`` (uniform)."""
    if layout == 'recommended':
        return recommended_directions(positions)
    if layout == 'random':
        return unit_directions(rng.standard_normal((positions, 3)))
    raise InputError(f'unknown layout {layout!r}; use recommended or random')


def simulate_position_means(truth: SensorModel, directions: np.ndarray, samples: int,
                            rng: np.random.Generator, rate_hz: float = SIM_RATE_HZ
                            ) -> Tuple[np.ndarray, Optional[np.ndarray]]:
    """
    Return mean raw readings (K, 3) in g and their noise of the mean (None for 1 sample).

    Same model as :class:`~accelcal_ros.driver.sim_sensor.SimulatedAdxl345` (truth
    distortion, datasheet noise at ``rate_hz``, 3.9 mg quantisation), vectorised.
    """
    raw = truth.distort(directions)
    noise = datasheet_noise_std_g(rate_hz)
    draws = raw[:, None, :] + rng.standard_normal((len(directions), samples, 3)) * noise
    draws = np.round(draws / FULL_RES_G_PER_LSB) * FULL_RES_G_PER_LSB
    means = draws.mean(axis=1)
    if samples < 2:
        return means, None
    return means, draws.std(axis=1, ddof=1) / np.sqrt(samples)


def _fit_trials(truth, positions, samples, count, seed, layout, model, retries=10):
    """Return (fitted SensorModels, refused count, mean fit time s, predicted errors)."""
    rng = np.random.default_rng(seed)
    models, predicted, refused, elapsed = [], [], 0, 0.0
    minimum = parameter_count(model)
    progress = Progress(count, f'fitting {count} simulated calibrations')
    while len(models) < count:
        directions = layout_directions(layout, positions, rng)
        means, stds = simulate_position_means(truth, directions, samples, rng)
        start = time.perf_counter()
        try:
            fit = fit_ellipsoid(means, stds, samples_per_position=samples, model=model,
                                drop_outliers=False, holdout=False, min_positions=minimum)
        except CalibrationError:
            refused += 1
            if refused > retries * count:
                break
            continue
        finally:
            elapsed += time.perf_counter() - start
        models.append(fit.sensor_model)
        predicted.append(fit.predicted_tilt_error_deg)
        progress.update()
    progress.close(erase=True)   # the caller prints the row
    return models, refused, elapsed / max(len(models) + refused, 1), predicted


def fitted_models(positions: int = 12, seconds_per_position: float = 1.0, count: int = 100,
                  seed: int = 0, layout: str = 'recommended',
                  model: str = 'full') -> List[SensorModel]:
    """
    Return ``count`` independent calibrations (SensorModel) of the default sim sensor.

    Each is fitted by the package's own LM fit from ``positions`` simulated captures
    (truth ``paper_a_model(500)`` = paper A K=500, datasheet noise, 100 Hz so that
    ``seconds_per_position`` = 1 averages 100 samples; at least one sample). A draw whose
    positions the fit refuses (random layouts with few positions) is replaced by a new one.
    """
    samples = max(1, int(round(seconds_per_position * SIM_RATE_HZ)))
    models, _, _, _ = _fit_trials(paper_a_model(500), positions, samples, count, seed, layout,
                                  model)
    if len(models) < count:
        raise CalibrationError(f'only {len(models)} of {count} simulated calibrations with '
                               f'{positions} {layout} positions could be fitted')
    return models


def error_statistics(truth: SensorModel, models: List[SensorModel]) -> dict:
    """Return a dict of parameter, unit-sphere and roll/pitch errors of fitted ``models``."""
    scale = np.array([m.scale for m in models])
    bias = np.array([m.bias for m in models])
    mis = np.array([m.misalignment for m in models])
    roll_err, pitch_err = tilt_errors_rad(truth, models)
    pooled = np.degrees(np.abs(np.concatenate([roll_err.ravel(), pitch_err.ravel()])))
    grid_force = specific_force_from_roll_pitch(TEST_GRID[:, 0], TEST_GRID[:, 1])
    raw = truth.distort(grid_force)
    lengths = np.array([np.linalg.norm(m.correct(raw), axis=1) for m in models])
    return {
        'scale_error_rms': float(np.sqrt(np.mean((scale - truth.scale) ** 2))),
        'bias_error_rms_mg': float(np.sqrt(np.mean((bias - truth.bias) ** 2)) * 1e3),
        'misalignment_error_rms_mrad': float(
            np.sqrt(np.mean((mis - truth.misalignment) ** 2)) * 1e3),
        'sphere_rms_mg': float(np.sqrt(np.mean((lengths - 1.0) ** 2)) * 1e3),
        'tilt_mean_deg': float(np.mean(pooled)),
        'tilt_p95_deg': float(np.percentile(pooled, 95.0)),
        'tilt_max_deg': float(np.max(pooled)),
    }


def study_row(truth: SensorModel, positions: int, samples: int, trials: int, seed: int,
              layout: str, model: str) -> dict:
    """Return one study row (dict) for a configuration, or one saying it was refused."""
    models, refused, fit_s, predicted = _fit_trials(truth, positions, samples, trials, seed,
                                                    layout, model, retries=2)
    row = {'positions': positions, 'layout': layout, 'samples': samples, 'model': model,
           'fitted': len(models), 'refused': refused, 'fit_ms': fit_s * 1e3}
    if models:
        row.update(error_statistics(truth, models))
        row['predicted_p95_deg'] = float(np.median(predicted))
    return row


def paper_worked_example() -> List[dict]:
    """
    Recompute paper A's worked example with the package's own code; returns rows (dicts).

    What the paper computed (p. 44): the K = 500 set is taken as the truth, a level
    sensor's raw reading is ``a = K500 [0, 0, -1] + b500`` (the paper's level reads
    ``[0, 0, -1]``: its ``g`` is gravity, i.e. minus the REP-145 specific force), it is
    corrected with the K = 100 or K = 300 set by eq. (4), and pitch follows from eq. (3).
    Here: ``SensorModel(K500).distort(f)`` then ``SensorModel(K100 or K300).correct(...)``
    with ``f = [0, 0, -1]`` (the paper's case) and ``f = [0, 0, +1]`` (a real level
    ADXL345, REP-145), and pitch from :func:`accelcal_ros.frames.paper_roll_pitch` (which
    equals :func:`~accelcal_ros.frames.roll_pitch_from_specific_force`'s pitch).
    """
    truth = paper_a_model(500)
    sets = {100: paper_a_model(100), 300: paper_a_model(300)}
    rows = []
    for k, estimate in sets.items():
        paper_case = estimate.correct(truth.distort(np.array([0.0, 0.0, -1.0])))
        _, pitch_paper_case = paper_roll_pitch(paper_case)
        _, pitch_rep = roll_pitch_from_specific_force(paper_case)
        upright = estimate.correct(truth.distort(np.array([0.0, 0.0, 1.0])))
        _, pitch_upright = roll_pitch_from_specific_force(upright)
        _, pitch_printed = paper_roll_pitch(np.array(PAPER_LEVEL_VECTORS[k]))
        rows.append({
            'positions': k,
            'paper_vector': PAPER_LEVEL_VECTORS[k],
            'paper_pitch_error_deg': PAPER_PITCH_ERRORS_DEG[k],
            'corrected_paper_level': paper_case,
            'pitch_error_paper_level_deg': abs(float(np.degrees(pitch_paper_case))),
            'pitch_error_rep103_formula_deg': abs(float(np.degrees(pitch_rep))),
            'pitch_from_printed_vector_deg': abs(float(np.degrees(pitch_printed))),
            'corrected_upright': upright,
            'pitch_error_upright_deg': abs(float(np.degrees(pitch_upright))),
        })
    return rows


def format_worked_example(rows: List[dict]) -> List[str]:
    """Return the worked example as printable lines."""
    lines = ["Paper A worked example (level sensor, K=500 as truth; paper's level = "
             '[0, 0, -1])']
    for r in rows:
        vec = ', '.join(f'{v:.4f}' for v in r['corrected_paper_level'])
        printed = ', '.join(f'{v:g}' for v in r['paper_vector'])
        up = ', '.join(f'{v:.4f}' for v in r['corrected_upright'])
        lines.append(
            f"  K={r['positions']}: package corrected [{vec}] -> pitch error "
            f"{r['pitch_error_paper_level_deg']:.2f} deg (paper: [{printed}] -> "
            f"{r['paper_pitch_error_deg']:.2f} deg; pitch of the paper's printed vector "
            f"{r['pitch_from_printed_vector_deg']:.2f} deg)")
        lines.append(f'         REP-145 upright level sensor: [{up}] -> '
                     f"{r['pitch_error_upright_deg']:.2f} deg")
    return lines


def run_study(trials: int = 100, seed: int = 0, counts: Sequence[int] = POSITION_COUNTS,
              models: Sequence[str] = ('diagonal', 'full'),
              layouts: Sequence[str] = ('random', 'recommended'),
              samples_options: Sequence[int] = (1, 100),
              say: Callable[..., None] = print) -> List[dict]:
    """Run the study, printing a table with ``say``; returns the rows."""
    truth = paper_a_model(500)
    rows = []
    say(f'Calibration accuracy study: truth = paper A K=500 (scale {truth.scale.tolist()}, '
        f'bias {truth.bias.tolist()} g), ADXL345 datasheet noise at 100 Hz, {trials} trials '
        'per row (fit/ref: fitted / refused draws, a refused draw is replaced); roll/pitch '
        'errors pooled over a grid of 132 orientations (roll -180..150 step 30, pitch '
        '-75..75 step 15 deg); scale err: RMS; bias: RMS mg; sphere: RMS of |f| - 1 in mg; '
        'pred p95: median p95 predicted by each fit from its covariance')
    header = (f'{"K":>4} {"layout":>11} {"per pos":>8} {"model":>8} {"fit/ref":>7} '
              f'{"scale err":>9} {"bias mg":>8} {"sphere mg":>9} {"mean deg":>8} '
              f'{"p95 deg":>8} {"max deg":>8} {"pred p95":>8} {"fit ms":>7}')
    say(header)
    for positions in counts:
        for layout in layouts:
            if layout == 'recommended' and positions < 6:
                continue
            for samples in samples_options:
                for model in models:
                    if positions < parameter_count(model):
                        continue
                    row = study_row(truth, positions, samples, trials, seed, layout, model)
                    rows.append(row)
                    say(format_row(row))
    return rows


def format_row(row: dict) -> str:
    """Return one printable line of a study row."""
    per = '1 sample' if row['samples'] == 1 else f'{row["samples"] / SIM_RATE_HZ:g} s'
    head = (f'{row["positions"]:>4} {row["layout"]:>11} {per:>8} {row["model"]:>8} '
            f'{row["fitted"]:>3}/{row["refused"]:<3}')
    if not row['fitted']:
        return head + f'  refused in all {row["refused"]} draws (positions do not constrain ' \
                      'the model)'
    return head + (f' {row["scale_error_rms"]:>9.5f} {row["bias_error_rms_mg"]:>8.2f} '
                   f'{row["sphere_rms_mg"]:>9.2f} {row["tilt_mean_deg"]:>8.4f} '
                   f'{row["tilt_p95_deg"]:>8.4f} {row["tilt_max_deg"]:>8.3f} '
                   f'{row["predicted_p95_deg"]:>8.4f} {row["fit_ms"]:>7.2f}')


def run_real_like(trials: int = 100, seed: int = 0,
                  say: Callable[..., None] = print) -> List[dict]:
    """Diagonal vs full model on a sensor with ~1 % cross-axis coupling; returns rows."""
    truth = paper_a_model(500)
    truth = SensorModel(truth.scale, truth.bias, np.array(REAL_LIKE_MISALIGNMENT))
    say(f'Real-like sensor: paper K=500 scale/bias plus misalignment '
        f'{list(REAL_LIKE_MISALIGNMENT)} rad (~1 % cross-axis coupling)')
    rows = []
    for positions in (12, 24):
        for model in ('diagonal', 'full'):
            row = study_row(truth, positions, 100, trials, seed, 'recommended', model)
            rows.append(row)
            say(format_row(row))
    return rows
