r"""
Paper A, Table 2: P2P yaw and range errors caused by accelerometer tilt errors (pure core).

``accelcal study p2p``. Monte Carlo over random camera attitudes; each trial solves the
P2P problem of :mod:`accelcal_ros.p2p.solver` with the true image rays and a vertical
corrupted by (a) the tilt error a calibration set produces and (b) 0.05 deg RMS noise on
roll and pitch, and compares yaw and range with the truth.

Modelling choices (the paper leaves them open; its simulation model is in its refs. 15-16)
----------------------------------------------------------------------------------------
- Scale-free geometry: the emitters' midpoint is the object origin, at range ``D`` from
  the camera; the baseline is ``0.25 D`` and **horizontal** (both emitters at one
  height, as the paper's ``t_z`` formula with ``M2 - M1`` along one object axis
  implies). The camera looks down at the emitters from the elevation ``elevation_deg``
  (default 30 deg: the camera is ``D sin 30 = 0.5 D`` above the emitters).
- Random attitude per trial: yaw uniform over the full circle (line-of-sight azimuth
  uniform, plus a pointing offset uniform in +-``pointing_deg``), pitch
  ``elevation_deg`` plus a pointing offset uniform in +-``pointing_deg`` (REP-103: positive
  pitch looks down), roll uniform in +-``roll_deg``. The baseline is within
  +-``aspect_deg`` of perpendicular to the line of sight (seen broadside, never
  end-on: end-on the two emitters fall on one ray).
- The IMU is mounted on the camera with :data:`~accelcal_ros.frames.DEFAULT_IMU_TO_CAMERA`
  and is calibrated perfectly except for the calibration set under test: the truth is
  paper A's K = 500 estimate (``paper_a_model(500)``); the raw reading of the true specific
  force ``f`` is ``a = truth.distort(f)`` and the attitude comes from
  ``est.correct(a)`` (REP-103 roll/pitch). Then 0.05 deg RMS Gaussian noise is added to
  roll and pitch independently. Image points are exact (the paper names no pixel noise);
  ``pixel_noise`` (normalised image units) can add it.
- Rows ``K=300 pitch only`` / ``K=100 pitch only`` replace the calibration set by the
  constant pitch error of paper A's worked example (1.53 / 3.31 deg, no roll error), which
  is what the paper's text discusses. Table 1's K=300 set also gives a roll error of
  about 3.6 deg near level (``(b500_y - b300_y) / k300_y``), which the paper does not
  mention: with the full per-trial tilt error K=300 is worse than K=100 here.
- The tilt error column is the RMS of roll and pitch errors pooled (noise included).
- Of two valid roots the one nearer the truth is kept (what the ``p2p`` node's
  continuity does); the horizontal baseline makes the root unique anyway.
- Errors: yaw error ``|wrap(yaw_est - yaw_true)|`` (deg, yaw of
  :func:`~accelcal_ros.p2p.solver.yaw_from_rotation`), range error
  ``| ||t_est|| - ||t|| | / ||t||`` (%, distance to the emitters' midpoint). The table
  shows the RMS over the trials beside the paper's figures (the paper does not say
  whether it reports RMS or mean absolute values; the mean is given too).

The geometry matters: with a horizontal baseline the range comes from the emitters'
elevation angles (``lambda_1 r_1z = lambda_2 r_2z``), so a camera at the emitters' height
cannot measure range at all and a small elevation magnifies tilt errors roughly as
``1 / tan(elevation)``; :func:`elevation_sweep` shows it.
"""
from dataclasses import asdict, dataclass
from typing import Any, Dict, Optional, Sequence, Tuple

from accelcal_ros.frames import (DEFAULT_IMU_TO_CAMERA, roll_pitch_from_specific_force,
                                 rotation_from_rpy_radians, specific_force_from_roll_pitch)
from accelcal_ros.p2p.solver import down_from_roll_pitch, solve_batch, yaw_from_rotation
from accelcal_ros.recording.progress import track
from accelcal_ros.sensor.model import (paper_a_model, PAPER_K100_BIAS, PAPER_K100_SCALE,
                                       PAPER_K300_BIAS, PAPER_K300_SCALE, SensorModel)
import numpy as np

PAPER_TABLE2 = {'K=500': (0.12, 0.17), 'K=300': (1.95, 2.20), 'K=100': (4.03, 4.31),
                'K=300 pitch only': (1.95, 2.20), 'K=100 pitch only': (4.03, 4.31)}
"""Paper A Table 2: (yaw error deg, range error %) per calibration set."""
PAPER_LEVEL_PITCH_ERROR_DEG = {'K=300': 1.53, 'K=100': 3.31}
"""Paper A's worked example: pitch error of a level sensor corrected with K=300 / K=100."""


@dataclass(frozen=True)
class StudyGeometry:
    """Scene and noise of the study; angles in degrees (see the module text)."""

    baseline_ratio: float = 0.25
    elevation_deg: float = 30.0
    roll_deg: float = 30.0
    pointing_deg: float = 10.0
    aspect_deg: float = 45.0
    tilt_noise_deg: float = 0.05
    pixel_noise: float = 0.0


@dataclass
class Scenes:
    """``N`` true problems: rotations, translations, emitter points, rays, body attitude."""

    rotations: np.ndarray
    translations: np.ndarray
    points: np.ndarray
    rays: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    yaw: np.ndarray


def random_scenes(count: int, rng: np.random.Generator,
                  geometry: 'StudyGeometry' = StudyGeometry(), range_m: float = 1.0) -> 'Scenes':
    """Draw ``count`` scenes of :class:`StudyGeometry` (object to camera poses, rays)."""
    g = geometry
    azimuth = rng.uniform(-np.pi, np.pi, count)
    elevation = np.radians(g.elevation_deg)
    yaw = azimuth + np.radians(rng.uniform(-g.pointing_deg, g.pointing_deg, count))
    yaw = np.angle(np.exp(1j * yaw))
    pitch = elevation + np.radians(rng.uniform(-g.pointing_deg, g.pointing_deg, count))
    roll = np.radians(rng.uniform(-g.roll_deg, g.roll_deg, count))
    los = np.stack([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth),
                    np.full(count, -np.sin(elevation))], axis=1)
    centre = -range_m * los                                    # camera in the object frame
    side = azimuth + np.pi / 2 + np.radians(rng.uniform(-g.aspect_deg, g.aspect_deg, count))
    half = 0.5 * g.baseline_ratio * range_m
    direction = np.stack([np.cos(side), np.sin(side), np.zeros(count)], axis=1)
    points = np.stack([-half * direction, half * direction], axis=1)
    body = np.stack([rotation_from_rpy_radians(r, p, y) for r, p, y in zip(roll, pitch, yaw)])
    rotations = np.einsum('ij,nkj->nik', DEFAULT_IMU_TO_CAMERA, body)   # M R_body^T
    translations = -np.einsum('nij,nj->ni', rotations, centre)
    rays = np.einsum('nij,nkj->nki', rotations, points) + translations[:, None, :]
    return Scenes(rotations, translations, points, rays, roll, pitch, yaw)


def measured_roll_pitch(roll: np.ndarray, pitch: np.ndarray, estimate: Any,
                        truth: Any = None) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the roll/pitch (rad) an IMU calibrated with ``estimate`` reports at true roll/pitch.

    ``a = truth.distort(f)``, ``f_est = estimate.correct(a)``, REP-103 roll/pitch of
    ``f_est``; ``estimate`` is a SensorModel or a list of them (used in turn per trial).
    """
    truth = truth or paper_a_model(500)
    force = specific_force_from_roll_pitch(roll, pitch)
    raw = truth.distort(force)
    models = estimate if isinstance(estimate, (list, tuple)) else [estimate]
    corrected = np.empty_like(raw)
    index = np.arange(len(raw)) % len(models)
    for k, model in enumerate(models):
        pick = index == k
        corrected[pick] = model.correct(raw[pick])
    return roll_pitch_from_specific_force(corrected)


class TiltOffset:
    """A constant roll/pitch error (deg) in place of a calibration set (paper A's examples)."""

    def __init__(self, roll_deg: float = 0.0, pitch_deg: float = 0.0) -> None:
        self.roll_deg, self.pitch_deg = float(roll_deg), float(pitch_deg)


def run_trials(scenes: 'Scenes', estimate: Any, geometry: 'StudyGeometry',
               rng: np.random.Generator) -> Dict[str, Any]:
    """
    Solve every scene with the vertical from ``estimate``; return the error statistics.

    ``estimate``: a SensorModel, a list of them, or a :class:`TiltOffset`.

    Returns a dict: ``tilt_rms_deg`` (roll/pitch error incl. noise, RMS of both), yaw and
    range error RMS/mean/median/p95, ``failed`` (no valid solution) and ``ambiguous``
    (two valid roots) counts.
    """
    if isinstance(estimate, TiltOffset):
        roll = scenes.roll + np.radians(estimate.roll_deg)
        pitch = scenes.pitch + np.radians(estimate.pitch_deg)
    else:
        roll, pitch = measured_roll_pitch(scenes.roll, scenes.pitch, estimate)
    sigma = np.radians(geometry.tilt_noise_deg)
    roll = roll + rng.standard_normal(roll.shape) * sigma
    pitch = pitch + rng.standard_normal(pitch.shape) * sigma
    tilt_error = np.degrees(np.concatenate([np.angle(np.exp(1j * (roll - scenes.roll))),
                                            pitch - scenes.pitch]))
    down = down_from_roll_pitch(roll, pitch)
    rays = scenes.rays / scenes.rays[:, :, 2:3]
    if geometry.pixel_noise > 0:
        rays = rays.copy()
        rays[:, :, :2] += rng.standard_normal(rays[:, :, :2].shape) * geometry.pixel_noise
    result = solve_batch(rays, scenes.points, down)
    ok = result.valid[:, 0]
    distance = np.linalg.norm(result.translations - scenes.translations[:, None, :], axis=2)
    distance = np.where(result.valid, distance, np.inf)
    best = np.argmin(distance, axis=1)
    take = np.arange(len(best))
    yaw_est = result.yaw[take, best]
    range_est = np.linalg.norm(result.translations[take, best], axis=1)
    range_true = np.linalg.norm(scenes.translations, axis=1)
    yaw_true = yaw_from_rotation(scenes.rotations)
    yaw_err = np.degrees(np.abs(np.angle(np.exp(1j * (yaw_est - yaw_true)))))[ok]
    range_err = (100.0 * np.abs(range_est - range_true) / range_true)[ok]

    def stats(values: np.ndarray) -> Dict[str, float]:
        if values.size == 0:
            return {'rms': float('nan'), 'mean': float('nan'), 'median': float('nan'),
                    'p95': float('nan')}
        return {'rms': float(np.sqrt(np.mean(values ** 2))), 'mean': float(np.mean(values)),
                'median': float(np.median(values)), 'p95': float(np.percentile(values, 95))}

    return {'trials': int(len(ok)), 'failed': int((~ok).sum()),
            'ambiguous': int(result.valid.all(axis=1).sum()),
            'tilt_rms_deg': float(np.sqrt(np.mean(tilt_error ** 2))),
            'yaw_deg': stats(yaw_err), 'range_pct': stats(range_err)}


def paper_models() -> Dict[str, SensorModel]:
    """Return ``{label: SensorModel}`` for paper A's K = 500 (truth), 300 and 100 sets."""
    return {'K=500': paper_a_model(500),
            'K=300': SensorModel(np.array(PAPER_K300_SCALE), np.array(PAPER_K300_BIAS)),
            'K=100': SensorModel(np.array(PAPER_K100_SCALE), np.array(PAPER_K100_BIAS))}


def run_study(trials: int = 10000, seed: int = 0, geometry: 'StudyGeometry' = StudyGeometry(),
              own_models: Optional[Sequence[SensorModel]] = None) -> Dict[str, Any]:
    """
    Run Table 2 for the paper's three sets and, if given, ``own_models`` (a list).

    Every row uses the same ``trials`` scenes (common random numbers). Returns
    ``{'geometry': ..., 'rows': {label: stats}}``.
    """
    rng = np.random.default_rng(seed)
    scenes = random_scenes(trials, rng, geometry)
    rows = {}
    models: Dict[str, Any] = dict(paper_models())
    models['K=300 pitch only'] = TiltOffset(0.0, PAPER_LEVEL_PITCH_ERROR_DEG['K=300'])
    models['K=100 pitch only'] = TiltOffset(0.0, PAPER_LEVEL_PITCH_ERROR_DEG['K=100'])
    if own_models:
        models['K=12 (package)'] = list(own_models)
    for label, model in track(list(models.items()), f'p2p study ({trials} trials per row)'):
        rows[label] = run_trials(scenes, model, geometry, np.random.default_rng([seed, 1]))
    return {'geometry': asdict(geometry), 'trials': trials, 'seed': seed, 'rows': rows}


def elevation_sweep(elevations_deg: Sequence[float] = (5.0, 10.0, 20.0, 30.0, 45.0, 60.0),
                    trials: int = 2000, seed: int = 0, geometry: 'StudyGeometry' = StudyGeometry(),
                    labels: Sequence[str] = ('K=500', 'K=300')) -> Dict[float, Dict[str, Any]]:
    """Return ``{elevation: {label: stats}}``: the geometry dependence of the errors."""
    out = {}
    models = paper_models()
    for elevation in track(elevations_deg, 'p2p elevation sweep'):
        g = StudyGeometry(**dict(asdict(geometry), elevation_deg=float(elevation)))
        scenes = random_scenes(trials, np.random.default_rng(seed), g)
        out[float(elevation)] = {label: run_trials(scenes, models[label], g,
                                                   np.random.default_rng([seed, 1]))
                                 for label in labels}
    return out


def format_table(study: Dict[str, Any], sweep: Optional[Dict[float, Any]] = None) -> str:
    """Return the study as printable text (Table 2 beside the paper, then the sweep)."""
    g = study['geometry']
    lines = [
        f'P2P with known vertical, paper A Table 2: {study["trials"]} trials, seed '
        f'{study["seed"]}',
        f'geometry: baseline/range {g["baseline_ratio"]}, horizontal baseline, camera '
        f'{g["elevation_deg"]:g} deg above the emitters, roll +-{g["roll_deg"]:g} deg, '
        f'pointing +-{g["pointing_deg"]:g} deg, yaw uniform 360 deg; tilt noise '
        f'{g["tilt_noise_deg"]} deg RMS',
        '',
        f'{"calibration":<17} {"tilt err":>9} {"yaw err RMS":>12} {"(mean)":>8} '
        f'{"paper":>6} {"range err RMS":>14} {"(mean)":>8} {"paper":>6} {"failed":>7}',
        f'{"":<17} {"deg RMS":>9} {"deg":>12} {"":>8} {"deg":>6} {"%":>14} {"":>8} '
        f'{"%":>6}',
    ]
    for label, row in study['rows'].items():
        paper = PAPER_TABLE2.get(label)
        py = f'{paper[0]:.2f}' if paper else '-'
        pr = f'{paper[1]:.2f}' if paper else '-'
        lines.append(
            f'{label:<17} {row["tilt_rms_deg"]:>9.3f} {row["yaw_deg"]["rms"]:>12.3f} '
            f'{row["yaw_deg"]["mean"]:>8.3f} {py:>6} {row["range_pct"]["rms"]:>14.3f} '
            f'{row["range_pct"]["mean"]:>8.3f} {pr:>6} {row["failed"]:>7}')
    if sweep:
        labels = list(next(iter(sweep.values())))
        lines += ['', 'geometry dependence (RMS; camera elevation above the emitters):',
                  f'{"elevation deg":>13} ' + ' '.join(
                      f'{lab + " yaw deg":>15} {lab + " range %":>15}' for lab in labels)]
        for elevation, rows in sweep.items():
            lines.append(f'{elevation:>13g} ' + ' '.join(
                f'{rows[lab]["yaw_deg"]["rms"]:>15.3f} {rows[lab]["range_pct"]["rms"]:>15.3f}'
                for lab in labels))
    return '\n'.join(lines)
