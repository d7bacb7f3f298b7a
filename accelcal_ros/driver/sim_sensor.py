r"""
A simulated ADXL345 visiting a list of static orientations (pure core).

Truth model: :class:`~accelcal_ros.sensor.model.SensorModel` (default, passed
explicitly: ``paper_a_model(500)``, paper A's K = 500 estimates, scale [0.928, 0.909,
0.896], bias [-0.025, -0.037, -0.056] g). The sensor dwells ``dwell_s`` in each
orientation of ``poses`` (roll, pitch; REP-103) and turns smoothly in ``move_s`` to the
next (slerp with a smoothstep profile), cycling.

Noise (:mod:`accelcal_ros.sensor.datasheet`; ADXL345 datasheet, Rev. G, Table 1): 0.75
LSB rms on x and y, 1.1 LSB rms on z at 100 Hz output data rate, with 3.9 mg/LSB in
full resolution, i.e. 2.9 mg and 4.3 mg. White noise over a bandwidth of ODR/2 scales
with ``sqrt(ODR / 100 Hz)``. The datasheet figure is the noise of the quantised output,
so the analog noise drawn before quantisation has variance ``sigma^2 - LSB^2 / 12``.
Readings are quantised to the full-resolution LSB (3.9 mg) and clipped to +-range.
Everything is deterministic for a given ``seed`` (samples drawn in order).
"""
from typing import Iterable, Optional, Tuple

from accelcal_ros.errors import InputError
from accelcal_ros.frames import specific_force_from_roll_pitch
from accelcal_ros.sensor.datasheet import datasheet_noise_std_g, FULL_RES_G_PER_LSB, RANGES_G
from accelcal_ros.sensor.model import paper_a_model, SensorModel
import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation


def near_uniform_poses_deg(count: int = 24) -> np.ndarray:
    """
    ``count`` (roll, pitch) pairs in degrees whose gravity directions cover the sphere.

    Fibonacci-sphere directions of the specific force ``f``, converted with
    ``pitch = asin(-f_x)``, ``roll = atan2(f_y, f_z)``.
    """
    k = np.arange(count) + 0.5
    z = 1.0 - 2.0 * k / count
    azimuth = np.pi * (1.0 + 5.0 ** 0.5) * k
    r = np.sqrt(1.0 - z * z)
    f = np.stack([r * np.cos(azimuth), r * np.sin(azimuth), z], axis=1)
    pitch = np.degrees(np.arcsin(np.clip(-f[:, 0], -1.0, 1.0)))
    roll = np.degrees(np.arctan2(f[:, 1], f[:, 2]))
    return np.stack([roll, pitch], axis=1)


def poses_from_flat_list(values: Iterable[float]) -> np.ndarray:
    """``(K, 2)`` array of (roll, pitch) degrees from a flat list; empty -> built-in 24."""
    values = np.asarray(list(values), dtype=float)
    if values.size == 0:
        return near_uniform_poses_deg(24)
    if values.size % 2:
        raise InputError(f'sim.poses_deg needs (roll, pitch) pairs; got {values.size} values')
    if not np.all(np.isfinite(values)):
        raise InputError('sim.poses_deg contains NaN or infinity')
    return values.reshape(-1, 2)


class SimulatedAdxl345:
    """Deterministic simulated ADXL345 following a dwell/move schedule of orientations."""

    def __init__(self, truth: Optional[SensorModel] = None, rate_hz: float = 100.0,
                 range_g: int = 16, poses_deg: Optional[ArrayLike] = None, dwell_s: float = 3.0,
                 move_s: float = 1.0, seed: int = 0, noise_scale: float = 1.0) -> None:
        if range_g not in RANGES_G:
            raise InputError(f'range_g must be one of {RANGES_G}, got {range_g}')
        if rate_hz <= 0 or dwell_s <= 0 or move_s < 0:
            raise InputError('rate_hz and dwell_s must be positive, move_s non-negative')
        self.truth = truth if truth is not None else paper_a_model(500)
        self.rate_hz = float(rate_hz)
        self.range_g = range_g
        poses = near_uniform_poses_deg(24) if poses_deg is None else np.asarray(poses_deg)
        self.poses_deg = np.asarray(poses, dtype=float).reshape(-1, 2)
        self.dwell_s = float(dwell_s)
        self.move_s = float(move_s)
        self.noise_std_g = datasheet_noise_std_g(self.rate_hz) * noise_scale
        # the datasheet figure is the noise of the quantised output: draw the analog part
        quantisation_var = FULL_RES_G_PER_LSB ** 2 / 12.0
        self._analog_std_g = np.sqrt(np.maximum(self.noise_std_g ** 2 - quantisation_var, 0.0))
        self._rng = np.random.default_rng(seed)
        rpy = np.zeros((len(self.poses_deg), 3))
        rpy[:, :2] = np.radians(self.poses_deg)
        self._rotations = Rotation.from_euler('xyz', rpy)  # extrinsic: Rz Ry Rx

    @property
    def period_s(self) -> float:
        """Time of one dwell plus one move."""
        return self.dwell_s + self.move_s

    def pose_index(self, t: ArrayLike) -> np.ndarray:
        """Index of the orientation dwelt in at time ``t`` (s), or -1 while moving."""
        t = np.asarray(t, dtype=float)
        phase = np.mod(t, self.period_s)
        index = np.floor_divide(t, self.period_s).astype(int) % len(self.poses_deg)
        return np.where(phase < self.dwell_s, index, -1)

    def attitude_at(self, t: ArrayLike) -> Tuple[np.ndarray, np.ndarray]:
        """
        Return the true (roll, pitch) in radians at times ``t`` (s), arrays of ``t``'s shape.

        Dwell: the pose's attitude. Move: ``R(u) = R_a exp(u log(R_a^T R_b))`` (slerp) with
        the smoothstep profile ``u = 3w^2 - 2w^3`` of the elapsed fraction ``w``.
        """
        times: np.ndarray = np.atleast_1d(np.asarray(t, dtype=float))
        n = len(self.poses_deg)
        cycle = np.floor_divide(times, self.period_s).astype(int)
        phase = times - cycle * self.period_s
        start = cycle % n
        end = (start + 1) % n
        w = np.clip((phase - self.dwell_s) / max(self.move_s, 1e-12), 0.0, 1.0)
        u = w * w * (3.0 - 2.0 * w)
        rot_start = self._rotations[start]
        delta = (rot_start.inv() * self._rotations[end]).as_rotvec()
        rotation = rot_start * Rotation.from_rotvec(u[:, None] * delta)
        euler = rotation.as_euler('xyz')
        return euler[:, 0], euler[:, 1]

    def true_specific_force(self, t: ArrayLike) -> np.ndarray:
        """Return the unit specific force in the body frame (g) at times ``t``: ``(N, 3)``."""
        roll, pitch = self.attitude_at(t)
        return specific_force_from_roll_pitch(roll, pitch)

    def read(self, t: ArrayLike) -> np.ndarray:
        """
        Return raw readings in g at times ``t`` (s): model, noise, quantisation, clipping.

        Draws noise in order from the seeded generator: call with increasing times.
        """
        return self.read_with_truth(t)[0]

    def read_with_truth(self, t: ArrayLike) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return ``(readings (N, 3) g, roll (N,) rad, pitch (N,) rad)`` at times ``t``."""
        roll, pitch = self.attitude_at(t)
        raw = self.truth.distort(specific_force_from_roll_pitch(roll, pitch))
        raw = raw + self._rng.standard_normal(raw.shape) * self._analog_std_g
        counts = np.round(raw / FULL_RES_G_PER_LSB)
        limit = self.range_g / FULL_RES_G_PER_LSB
        return np.clip(counts, -limit, limit - 1) * FULL_RES_G_PER_LSB, roll, pitch
