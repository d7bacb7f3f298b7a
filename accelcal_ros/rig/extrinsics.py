r"""
Rig extrinsics ``R_0i``, ``t_0i``: one least-squares problem over all board views.

Model. Board pose ``k`` in the reference camera: ``X_0 = R_0b,k X_b + t_0b,k``; camera
``i``: ``X_i = R_0i X_0 + t_0i`` (``R_00 = I``, ``t_00 = 0``). A corner ``X_b`` seen by
camera ``i`` in pose ``k`` is predicted at ``project_i(R_0i (R_0b,k X_b + t_0b,k) +
t_0i)`` (its ``K_i``, ``D_i`` held fixed) and

.. math::  \min \sum_{k, i} \sum_{corners} \| x_{ki} - \hat x_{ki} \|^2

is solved by ``scipy.optimize.least_squares`` (Levenberg-Marquardt) over every board
pose and every non-reference camera's ``(R_0i, t_0i)`` at once; the Jacobian is taken
by central differences, grouped since a view depends on its pose and camera only.
Rotations are updated on the right,
``R = R_init exp([d]_x)``, so ``d`` of ``R_0i`` is a small rotation about the reference
camera's own x (right), y (down), z (forward) axes.

Start. Every view's board pose from ``cv2.solvePnP``; cameras are chained from the
reference through the camera pairs that share most views (``R_0j`` from ``R_jb R_ib^T
R_0i`` averaged over the shared poses with ``Rotation.mean``).

Uncertainty. ``cov = s^2 (J^T J)^{-1}`` at the solution, ``s^2`` the residual variance
per pixel coordinate; the 1-sigma angle of each ``d`` component, in degrees.
"""
from dataclasses import dataclass, field
import time
from typing import Dict, List, Sequence, Tuple

from accelcal_ros.errors import CalibrationError
from accelcal_ros.rig.intrinsics import views_over_limit
import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

View = Tuple[str, int]
"""``(pose name, camera index)``."""


@dataclass
class RigFit:
    """Result of the joint fit; camera 0 is the reference."""

    rotations: List[np.ndarray]
    translations_m: List[np.ndarray]
    rotation_std_deg: List[np.ndarray]
    translation_std_m: List[np.ndarray]
    board_poses: Dict[str, Tuple[np.ndarray, np.ndarray]]
    board_rotation_std_deg: Dict[str, float]
    view_rms_px: Dict[View, float]
    rms_px: float
    shared_views: np.ndarray
    fit_time_s: float
    dropped: Dict[View, str] = field(default_factory=dict)
    lenses: List[Tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    lens_std: List[np.ndarray] = field(default_factory=list)


def _pnp(obj: np.ndarray, corners: np.ndarray, k: np.ndarray,
         d: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    ok, rvec, tvec = cv2.solvePnP(obj, corners, k, d, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        ok, rvec, tvec = cv2.solvePnP(obj, corners, k, d)
    rvec, tvec = cv2.solvePnPRefineLM(obj, corners, k, d, rvec, tvec)
    return cv2.Rodrigues(rvec)[0], tvec.ravel()


def shared_view_counts(views: Sequence[View], n_cam: int) -> np.ndarray:
    """``(n, n)`` counts of poses in which both cameras see the board (diagonal: views)."""
    by_pose: Dict[str, List[int]] = {}
    for pose, cam in views:
        by_pose.setdefault(pose, []).append(cam)
    counts = np.zeros((n_cam, n_cam), dtype=int)
    for cams in by_pose.values():
        for i in cams:
            for j in cams:
                counts[i, j] += 1
    return counts


def _chain(poses_cam: Dict[View, Tuple[np.ndarray, np.ndarray]], counts: np.ndarray,
           names: Sequence[str]) -> List[Tuple[np.ndarray, np.ndarray]]:
    n = len(names)
    known = {0: (np.eye(3), np.zeros(3))}
    by_pose: Dict[str, Dict[int, Tuple[np.ndarray, np.ndarray]]] = {}
    for (pose, cam), value in poses_cam.items():
        by_pose.setdefault(pose, {})[cam] = value
    while len(known) < n:
        best = max(((counts[i, j], i, j) for i in known for j in range(n) if j not in known),
                   default=(0, -1, -1))
        if best[0] == 0:
            missing = [names[j] for j in range(n) if j not in known]
            raise CalibrationError(
                f'camera(s) {", ".join(missing)} never see the board in a pose where a '
                f'calibrated camera sees it too: add poses with the board where '
                f'{missing[0]} and a neighbouring camera both see all of it')
        _, i, j = best
        r_0i, t_0i = known[i]
        rots, trans = [], []
        for cams in by_pose.values():
            if i in cams and j in cams:
                r_ib, t_ib = cams[i]
                r_jb, t_jb = cams[j]
                r_ji = r_jb @ r_ib.T  # camera i -> camera j
                rots.append(r_ji @ r_0i)
                trans.append(r_ji @ (t_0i - t_ib) + t_jb)
        known[j] = (Rotation.from_matrix(np.array(rots)).mean().as_matrix(),
                    np.mean(trans, axis=0))
    return [known[i] for i in range(n)]


INTRINSIC_STEPS = np.array([1e-3, 1e-3, 1e-3, 1e-3, 1e-6, 1e-6, 1e-7, 1e-7])
"""Difference steps of ``fx, fy, cx, cy`` (px) and ``k1, k2, p1, p2``."""


class _Problem:
    # Parameters: [camera 1..n-1: d(3), dt(3)] [free camera: dfx, dfy, dcx, dcy, dk1, dk2,
    # dp1, dp2] [pose: d(3), dt(3)], all increments on the starting values.
    def __init__(self, views, obs, obj, intrinsics, free, cams0, boards0):
        self.views = views
        self.obs = obs
        self.obj = obj
        self.intrinsics = intrinsics
        self.cams0 = cams0
        self.pose_names = sorted({p for p, _ in views})
        self.pose_index = {p: k for k, p in enumerate(self.pose_names)}
        self.boards0 = [boards0[p] for p in self.pose_names]
        self.n_cam = len(cams0)
        self.extr = {i: 6 * (i - 1) for i in range(1, self.n_cam)}
        base = 6 * (self.n_cam - 1)
        self.intr = {}
        for i in range(self.n_cam):
            if free[i]:
                self.intr[i] = base
                base += 8
        self.pose_base = base
        self.size = base + 6 * len(self.pose_names)

    def unpack(self, x):
        cams = [(np.eye(3), np.zeros(3))]
        for i in range(1, self.n_cam):
            p = x[self.extr[i]:self.extr[i] + 6]
            cams.append((self.cams0[i][0] @ Rotation.from_rotvec(p[:3]).as_matrix(),
                         self.cams0[i][1] + p[3:]))
        lenses = []
        for i in range(self.n_cam):
            k, d = self.intrinsics[i]
            k = np.array(k, dtype=float)
            d = np.array(d, dtype=float)
            if i in self.intr:
                p = x[self.intr[i]:self.intr[i] + 8]
                k[0, 0] += p[0]
                k[1, 1] += p[1]
                k[0, 2] += p[2]
                k[1, 2] += p[3]
                d[:4] += p[4:]
            lenses.append((k, d))
        boards = []
        for k in range(len(self.pose_names)):
            p = x[self.pose_base + 6 * k:self.pose_base + 6 * k + 6]
            boards.append((self.boards0[k][0] @ Rotation.from_rotvec(p[:3]).as_matrix(),
                           self.boards0[k][1] + p[3:]))
        return cams, lenses, boards

    def residuals(self, x):
        cams, lenses, boards = self.unpack(x)
        out = []
        for pose, cam in self.views:
            r_0b, t_0b = boards[self.pose_index[pose]]
            r_0i, t_0i = cams[cam]
            k, d = lenses[cam]
            rvec = cv2.Rodrigues(r_0i @ r_0b)[0]
            px, _ = cv2.projectPoints(self.obj, rvec, r_0i @ t_0b + t_0i, k, d)
            out.append((px.reshape(-1, 2) - self.obs[(pose, cam)]).ravel())
        return np.concatenate(out)

    def jacobian(self, x):
        # Central differences, grouped: slot j of every camera (or every board pose) is
        # perturbed at once, since a view depends on its own camera and pose only.
        rows = 2 * len(self.obj)
        jac = np.zeros((rows * len(self.views), x.size))
        row_ids = np.arange(jac.shape[0])
        groups = [({self.extr[i] + j: i for i in self.extr}, 'cam', 1e-6) for j in range(6)]
        groups += [({self.intr[i] + j: i for i in self.intr}, 'cam', INTRINSIC_STEPS[j])
                   for j in range(8)]
        groups += [({self.pose_base + 6 * k + j: k for k in range(len(self.pose_names))},
                    'pose', 1e-6) for j in range(6)]
        owner = {'cam': np.repeat([c for _, c in self.views], rows),
                 'pose': np.repeat([self.pose_index[p] for p, _ in self.views], rows)}
        for columns, kind, step in groups:
            if not columns:
                continue
            dx = np.zeros_like(x)
            dx[list(columns)] = step
            diff = (self.residuals(x + dx) - self.residuals(x - dx)) / (2 * step)
            column_of = np.full(max(self.n_cam, len(self.pose_names)), -1)
            for col, who in columns.items():
                column_of[who] = col
            cols = column_of[owner[kind]]
            keep = cols >= 0
            jac[row_ids[keep], cols[keep]] = diff[keep]
        return jac


def _solve(problem: _Problem):
    x0 = np.zeros(problem.size)
    return least_squares(problem.residuals, x0, jac=problem.jacobian, method='lm',
                         xtol=1e-10, ftol=1e-10)


def fit_rig(observations: Dict[View, np.ndarray], object_points: np.ndarray,
            intrinsics: Sequence[Tuple[np.ndarray, np.ndarray]], names: Sequence[str],
            free_intrinsics: Sequence[bool] = (), max_view_rms_px: float = 1.0,
            drop_factor: float = 5.0) -> RigFit:
    """
    Fit ``R_0i``, ``t_0i`` and every board pose to ``observations`` (corners per view).

    ``intrinsics[i] = (K_i, D_i)`` start values; those of cameras flagged in
    ``free_intrinsics`` (``fx, fy, cx, cy, k1, k2, p1, p2``) are refined with the rest
    (bundle adjustment), the others held (e.g. read from a camera_info file). Views
    whose RMS after the fit exceeds
    ``max(max_view_rms_px, drop_factor x median)`` are dropped with the reason and the
    problem is solved again. Raises :class:`CalibrationError` when a camera cannot be
    linked to the reference.
    """
    start = time.perf_counter()
    obj = np.asarray(object_points, dtype=np.float64)
    n_cam = len(names)
    views = sorted(observations)
    free = list(free_intrinsics) + [False] * (n_cam - len(free_intrinsics))
    dropped: Dict[View, str] = {}
    for _ in range(3):
        counts = shared_view_counts(views, n_cam)
        for i in range(n_cam):
            if counts[i, i] == 0:
                raise CalibrationError(f'camera {names[i]} sees the board in no pose: add '
                                       f'poses with the whole board in its image')
        pnp = {v: _pnp(obj, observations[v], *intrinsics[v[1]]) for v in views}
        cams0 = _chain(pnp, counts, names)
        boards0 = {}
        for pose, cam in views:
            if pose not in boards0:
                r_ib, t_ib = pnp[(pose, cam)]
                r_0i, t_0i = cams0[cam]
                boards0[pose] = (r_0i.T @ r_ib, r_0i.T @ (t_ib - t_0i))
        problem = _Problem(views, observations, obj, intrinsics, free, cams0, boards0)
        res = _solve(problem)
        resid = res.fun.reshape(len(views), -1)
        view_rms = np.sqrt(np.mean(resid ** 2, axis=1))
        limit, bad = views_over_limit(list(zip(views, view_rms)), max_view_rms_px,
                                      drop_factor)
        if not bad:
            break
        for v, e in bad:
            dropped[v] = (f'rig fit: reprojection RMS {e:.2f} px > {limit:.2f} px (the '
                          'camera or board moved between views of this pose?)')
        views = [v for v in views if v not in dropped]
    cams, lenses, boards = problem.unpack(res.x)
    jac = res.jac.toarray() if hasattr(res.jac, 'toarray') else np.asarray(res.jac)
    dof = max(1, res.fun.size - res.x.size)
    s2 = float(res.fun @ res.fun / dof)
    try:
        cov = np.linalg.inv(jac.T @ jac) * s2
    except np.linalg.LinAlgError:
        cov = np.full((res.x.size, res.x.size), np.inf)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    rot_std = [np.zeros(3)] + [np.degrees(std[problem.extr[i]:problem.extr[i] + 3])
                               for i in range(1, n_cam)]
    trans_std = [np.zeros(3)] + [std[problem.extr[i] + 3:problem.extr[i] + 6]
                                 for i in range(1, n_cam)]
    lens_std = [std[problem.intr[i]:problem.intr[i] + 8] if i in problem.intr else np.zeros(8)
                for i in range(n_cam)]
    board_std = {}
    for k, pose in enumerate(problem.pose_names):
        j = problem.pose_base + 6 * k
        board_std[pose] = float(np.degrees(np.sqrt(np.trace(cov[j:j + 3, j:j + 3]) / 3.0)))
    return RigFit([c[0] for c in cams], [c[1] for c in cams], rot_std, trans_std,
                  dict(zip(problem.pose_names, boards)), board_std,
                  {v: float(e) for v, e in zip(views, view_rms)},
                  float(np.sqrt(np.mean(res.fun ** 2))), shared_view_counts(views, n_cam),
                  time.perf_counter() - start, dropped, lenses, lens_std)


def rotation_angle_deg(r1: np.ndarray, r2: np.ndarray) -> float:
    """Angle (deg) of the rotation ``r1 r2^T``."""
    return float(np.degrees(Rotation.from_matrix(np.asarray(r1) @ np.asarray(r2).T)
                            .magnitude()))
