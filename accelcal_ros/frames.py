r"""
Frame and sign conventions, fixed once for the whole package.

Body frame (REP-103): x forward, y left, z up. Attitude is the fixed-axis roll-pitch-yaw
rotation ``R = Rz(yaw) Ry(pitch) Rx(roll)`` taking body vectors into the level frame
(z up). Angles are radians everywhere in code; ``_deg`` in a name says degrees.

Specific force (REP-145): an accelerometer at rest reads the reaction to gravity, i.e.
``+1 g`` on the axis pointing up. In the body frame at rest,

.. math::  f = R^T [0, 0, 1]^T = [-\sin p,\ \sin r \cos p,\ \cos r \cos p]^T

so that ``roll = atan2(f_y, f_z)`` and ``pitch = atan2(-f_x, \sqrt{f_y^2 + f_z^2})``.

Paper A (Kalinkin et al. 2020, eqs. 2-3) writes ``roll = -atan2(g_y, g_z)`` and
``pitch = -atan2(g_x, \sqrt{g_y^2 + g_z^2})``, while its worked example treats a level
sensor as reading ``g = [0, 0, -1]`` (the gravity vector, ``g = -f``). The two do not
agree: eq. (2) on ``[0, 0, -1]`` gives a roll of 180 deg. What holds, and is tested
(``test/test_frames.py``):

- fed with the specific force ``f`` (level reads ``[0, 0, +1]``), eq. (3) is exactly the
  REP-103 pitch and eq. (2) is minus the REP-103 roll (the paper counts roll positive
  left side down);
- the worked example only uses pitch, whose magnitude is the same for ``g`` and ``-g``.

Decision: the package computes attitude only with
:func:`roll_pitch_from_specific_force` (REP-103). :func:`paper_roll_pitch` keeps eqs.
(2)-(3) literally for recomputing the paper's numbers, and
:func:`rep103_from_paper_roll_pitch` is the one place that maps the paper's angles.

Camera optical frames (REP-103 ``_optical``): z forward, x right, y down. The default
``imu_to_camera`` rotation is for a camera looking along body +x:
camera x = -body y, camera y = -body z, camera z = body x.
"""
import math
from typing import Optional, Tuple

from accelcal_ros.errors import InputError
import numpy as np
from numpy.typing import ArrayLike

DEFAULT_IMU_TO_CAMERA = np.array([[0.0, -1.0, 0.0],
                                  [0.0, 0.0, -1.0],
                                  [1.0, 0.0, 0.0]])
"""Body (x fwd, y left, z up) -> optical (x right, y down, z fwd), camera along body +x."""

ROLL_LIMIT_RAD = math.pi
PITCH_LIMIT_RAD = math.pi / 2
"""Range of an attitude (REP-103): roll in [-pi, pi], pitch in [-pi/2, pi/2]; anything else
(pitch 4 rad, roll 1e300) is not an attitude ``roll_pitch_from_specific_force`` returns."""


def attitude_problem(roll: float, pitch: float) -> Optional[str]:
    """
    Return why ``(roll, pitch)`` (rad) is not an attitude, or None when it is one.

    Finite, ``|roll| <= pi`` and ``|pitch| <= pi/2`` (a tiny rounding margin allowed), the
    range every attitude this package computes lies in. Used where an attitude enters (a
    message, an option, a file) so that a wrapped or absurd angle is refused, not used.
    """
    try:
        r, p = float(roll), float(pitch)
    except (TypeError, ValueError, OverflowError):
        return f'roll={roll!r}, pitch={pitch!r} are not numbers'
    if not (math.isfinite(r) and math.isfinite(p)):
        return f'roll={r}, pitch={p} is not finite'
    margin = 1e-9
    if abs(r) > ROLL_LIMIT_RAD + margin or abs(p) > PITCH_LIMIT_RAD + margin:
        return (f'roll={r:.6g} rad, pitch={p:.6g} rad is outside roll +-pi, pitch +-pi/2 '
                '(REP-103 attitude; degrees sent as radians?)')
    return None


def check_attitude(roll: float, pitch: float, where: str = 'attitude') -> Tuple[float, float]:
    """Return ``(roll, pitch)`` as floats; :class:`InputError` naming ``where`` if not one."""
    problem = attitude_problem(roll, pitch)
    if problem:
        raise InputError(f'{where}: {problem}')
    return float(roll), float(pitch)


def rot_x(angle_rad: float) -> np.ndarray:
    """Rotation matrix about x by ``angle_rad`` (right-handed, active)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle_rad: float) -> np.ndarray:
    """Rotation matrix about y by ``angle_rad`` (right-handed, active)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle_rad: float) -> np.ndarray:
    """Rotation matrix about z by ``angle_rad`` (right-handed, active)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_from_rpy_radians(roll: float, pitch: float, yaw: float = 0.0) -> np.ndarray:
    """Body-to-level rotation ``Rz(yaw) Ry(pitch) Rx(roll)`` (REP-103 fixed axes)."""
    return rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)


def rpy_radians_from_rotation(rotation: ArrayLike) -> Tuple[float, float, float]:
    """Inverse of :func:`rotation_from_rpy_radians`: ``(roll, pitch, yaw)`` in radians."""
    r = np.asarray(rotation, dtype=float)
    pitch = np.arctan2(-r[2, 0], np.hypot(r[2, 1], r[2, 2]))
    roll = np.arctan2(r[2, 1], r[2, 2])
    yaw = np.arctan2(r[1, 0], r[0, 0])
    return float(roll), float(pitch), float(yaw)


def specific_force_from_roll_pitch(roll: ArrayLike, pitch: ArrayLike) -> np.ndarray:
    """
    Return the unit specific force in the body frame at rest (REP-145, +z up when level).

    Vectorised: ``roll`` and ``pitch`` (radians) may be arrays; returns ``(..., 3)``.
    """
    roll = np.asarray(roll, dtype=float)
    pitch = np.asarray(pitch, dtype=float)
    return np.stack([-np.sin(pitch),
                     np.sin(roll) * np.cos(pitch),
                     np.cos(roll) * np.cos(pitch)], axis=-1)


def roll_pitch_from_specific_force(force: ArrayLike) -> Tuple[np.ndarray, np.ndarray]:
    """
    Roll and pitch (radians) from specific force ``(..., 3)`` in any consistent unit.

    ``roll = atan2(f_y, f_z)``, ``pitch = atan2(-f_x, sqrt(f_y^2 + f_z^2))``. Pitch is
    finite everywhere (``atan2`` of a non-negative second argument); at pitch = +-90 deg
    roll is undefined and comes out as ``atan2(0, 0) = 0`` -- never NaN.
    """
    f = np.asarray(force, dtype=float)
    roll = np.arctan2(f[..., 1], f[..., 2])
    pitch = np.arctan2(-f[..., 0], np.hypot(f[..., 1], f[..., 2]))
    return roll, pitch


def rep103_from_paper_roll_pitch(roll_paper: ArrayLike,
                                 pitch_paper: ArrayLike) -> Tuple[np.ndarray, np.ndarray]:
    """Map paper A's eqs. (2)-(3) angles (computed on ``f``) to REP-103: ``(-roll, pitch)``."""
    return -np.asarray(roll_paper, dtype=float), np.asarray(pitch_paper, dtype=float)


def paper_gravity_from_specific_force(force: ArrayLike) -> np.ndarray:
    """Paper A's measured vector ``g`` (level sensor reads [0, 0, -1]) from ``f``: ``g = -f``."""
    return -np.asarray(force, dtype=float)


def paper_roll_pitch(gravity: ArrayLike) -> Tuple[np.ndarray, np.ndarray]:
    """
    Apply paper A eqs. (2)-(3) literally to a measured vector.

    ``roll = -atan2(g_y, g_z)`` and ``pitch = -atan2(g_x, sqrt(g_y^2 + g_z^2))``. Kept so
    the paper's worked examples can be recomputed literally (see the module docstring
    for how its conventions relate to REP-103); everything else in this package uses
    :func:`roll_pitch_from_specific_force`.
    """
    g = np.asarray(gravity, dtype=float)
    roll = -np.arctan2(g[..., 1], g[..., 2])
    pitch = -np.arctan2(g[..., 0], np.hypot(g[..., 1], g[..., 2]))
    return roll, pitch


def down_in_camera(roll: ArrayLike, pitch: ArrayLike,
                   imu_to_camera: ArrayLike = DEFAULT_IMU_TO_CAMERA) -> np.ndarray:
    """Return the unit gravity direction ("down") in the camera frame from roll/pitch."""
    down_body = -specific_force_from_roll_pitch(roll, pitch)
    return np.asarray(imu_to_camera, dtype=float) @ down_body


def rotation_matrix_from_list(values: ArrayLike, name: str = 'rotation',
                              tolerance: float = 1e-6) -> np.ndarray:
    """
    3x3 rotation from 9 row-major numbers; raises :class:`InputError` if not a rotation.

    Accepts a small deviation (``tolerance`` on ``R R^T - I`` and on ``det R - 1``) so that
    values written with limited precision still load; the result is re-orthonormalised.
    """
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f'{name}: expected 9 row-major numbers, got {values!r:.80}') from None
    if arr.size != 9:
        raise InputError(f'{name}: expected 9 row-major values, got {arr.size}')
    r = arr.reshape(3, 3)
    if not np.all(np.isfinite(r)):
        raise InputError(f'{name}: contains NaN or infinity')
    if np.abs(r).max() > 1.0 + tolerance:
        raise InputError(f'{name}: not a rotation matrix (an entry is '
                         f'{r.flat[np.abs(r).argmax()]:.6g}; those of a rotation are within '
                         '+-1)')
    if (np.abs(r @ r.T - np.eye(3)).max() > tolerance
            or abs(np.linalg.det(r) - 1.0) > tolerance):
        raise InputError(f'{name}: not a rotation matrix (R R^T != I or det R != 1, '
                         f'det = {np.linalg.det(r):.6g})')
    u, _, vt = np.linalg.svd(r)
    return u @ vt
