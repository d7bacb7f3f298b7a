"""
Rig calibration of a capture directory, end to end (pure core; the CLI and node call it).

1. Detect the board in every image (:mod:`.detect`); a board of another size is named.
2. Intrinsics per camera (:mod:`.intrinsics`) or from ``--intrinsics`` files.
3. Joint fit of the rig, board poses and the free intrinsics (:mod:`.extrinsics`).
4. ``imu_to_camera`` and the board tilt from each still pose's gravity
   (:mod:`.imu_to_camera`).
5. Warnings for what the poses leave unconstrained, each saying what poses to add.
"""
from dataclasses import dataclass, field
import os
import time
from typing import Dict, List, Optional, Sequence, Tuple

from accelcal_ros.errors import CalibrationError, InputError
from accelcal_ros.rig.board import Board
from accelcal_ros.rig.dataset import (check_size, Dataset, pose_gravity, read_grey,
                                      scan_directory)
from accelcal_ros.rig.detect import detect_board, guess_board_size
from accelcal_ros.rig.extrinsics import fit_rig, RigFit
from accelcal_ros.rig.imu_to_camera import (fit_imu_to_camera, gravity_spread_warning,
                                            MountFit)
from accelcal_ros.rig.intrinsics import (calibrate_camera, coverage_fraction, Intrinsics,
                                         load_camera_info, per_view_errors)
from accelcal_ros.sensor.model import SensorModel
import numpy as np

MIN_VIEWS_PER_CAMERA = 6
MIN_SHARED_VIEWS = 3
MIN_COVERAGE = 0.5
MIN_GRAVITY_POSES = 2
"""Poses with both a board view and a still 1 g accelerometer log ``imu_to_camera`` needs."""


@dataclass
class RigCalibration:
    """Everything the rig file, the report and the plot need."""

    board: Board
    cameras: List[str]
    sizes: List[Tuple[int, int]]
    intrinsics: List[Intrinsics]
    fit: RigFit
    mount: MountFit
    gravity: Dict[str, np.ndarray]
    detections: Dict[Tuple[str, int], np.ndarray]
    coverage: List[float]
    no_board: List[str] = field(default_factory=list)
    dropped_views: Dict[str, str] = field(default_factory=dict)
    dropped_poses: Dict[str, str] = field(default_factory=dict)
    warnings: List[str] = field(default_factory=list)
    total_time_s: float = 0.0

    @property
    def K(self) -> List[np.ndarray]:
        """Return the final camera matrices (after the joint fit)."""
        return [lens[0] for lens in self.fit.lenses]

    @property
    def D(self) -> List[np.ndarray]:
        """Return the final distortion coefficients (after the joint fit)."""
        return [lens[1] for lens in self.fit.lenses]


def _detect_all(dataset: Dataset, board: Board
                ) -> Tuple[Dict[Tuple[str, int], np.ndarray], List[str]]:
    detections: Dict[Tuple[str, int], np.ndarray] = {}
    failed: List[str] = []
    for pose in dataset.poses:
        for i, cam in enumerate(dataset.cameras):
            path = dataset.image_path(pose, cam)
            if path is None:
                continue
            image = read_grey(path)
            check_size(dataset, cam, pose, image)
            found = detect_board(image, board)
            if found is None:
                failed.append(f'{pose}/{cam}')
            else:
                detections[(pose, i)] = found.corners
    if not detections:
        hints = []
        for pose in dataset.poses[:4]:
            for cam in dataset.cameras:
                path = dataset.image_path(pose, cam)
                if path is None:
                    continue
                other = guess_board_size(read_grey(path), board)
                if other:
                    hints.append(f'{pose}/{cam}.png shows a {other[0][0]}x{other[0][1]} board')
                    break
            if hints:
                break
        detail = (f'; {hints[0]} (inner corners as OpenCV counts): check --board'
                  if hints else ': is the whole board in view, sharp and well lit?')
        raise InputError(f'no {board.cols}x{board.rows} board found in any image of poses '
                         f'{", ".join(dataset.poses)}{detail}')
    return detections, failed


def _intrinsics(dataset: Dataset, board: Board,
                detections: Dict[Tuple[str, int], np.ndarray],
                files: Sequence[str]) -> List[Intrinsics]:
    given: Dict[str, Intrinsics] = {}
    for path in files:
        name, intr = load_camera_info(path)
        stem = os.path.splitext(os.path.basename(path))[0]
        cam = name if name in dataset.cameras else stem if stem in dataset.cameras else None
        if cam is None:
            raise InputError(f'--intrinsics {path}: camera_name {name!r} and file name '
                             f'{stem!r} match no camera ({", ".join(dataset.cameras)})')
        size = dataset.sizes.get(cam)
        if size is not None and tuple(intr.size) != tuple(size):
            raise InputError(f'--intrinsics {path} is for {intr.size[0]}x{intr.size[1]} images '
                             f'but camera {cam} took {size[0]}x{size[1]}: give the file of '
                             'this camera at this resolution')
        given[cam] = intr
    out = []
    obj = board.object_points()
    for i, cam in enumerate(dataset.cameras):
        views = {p: c for (p, j), c in detections.items() if j == i}
        if cam in given:
            intr = given[cam]
            intr.view_rms_px = per_view_errors(intr, views, obj)
            out.append(intr)
        else:
            out.append(calibrate_camera(cam, views, obj, dataset.sizes[cam]))
    return out


def _fov_overlap(k_i: np.ndarray, size_i: Tuple[int, int], r_i: np.ndarray,
                 k_j: np.ndarray, size_j: Tuple[int, int], r_j: np.ndarray) -> bool:
    half = [np.arctan(0.5 * s[0] / k[0, 0]) for k, s in ((k_i, size_i), (k_j, size_j))]
    angle = np.arccos(np.clip(r_i[2] @ r_j[2], -1.0, 1.0))
    return bool(angle < half[0] + half[1] - np.radians(10.0))


def _warnings(result: RigCalibration) -> List[str]:
    out = []
    names = result.cameras
    counts = result.fit.shared_views
    for i, cam in enumerate(names):
        if counts[i, i] < MIN_VIEWS_PER_CAMERA:
            out.append(f'camera {cam} has only {counts[i, i]} board views: add poses with the '
                       f'board in its image (near the corners, tilted), at least '
                       f'{MIN_VIEWS_PER_CAMERA}')
        if result.coverage[i] < MIN_COVERAGE and result.intrinsics[i].source == 'board views':
            out.append(f'camera {cam}: the board views cover {100 * result.coverage[i]:.0f} % '
                       f'of the image: add views with the board near the edges and corners')
    rots = result.fit.rotations
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if counts[i, j] >= MIN_SHARED_VIEWS:
                continue
            if _fov_overlap(result.K[i], result.sizes[i], rots[i], result.K[j],
                            result.sizes[j], rots[j]):
                out.append(f'cameras {names[i]} and {names[j]} share {counts[i, j]} views '
                           f'though their images overlap: add poses with the board where '
                           f'both see it (at least {MIN_SHARED_VIEWS})')
    out += result.mount.warnings
    out += gravity_spread_warning(result.gravity)
    return out


def _too_few_poses(count: int, dropped_poses: Dict[str, str], shown: int = 1) -> str:
    """Return the error of too few gravity poses, with why the first dropped ones went."""
    reasons = '; '.join(f'{pose}: {why}' for pose, why in sorted(dropped_poses.items())[:shown])
    more = f'; {len(dropped_poses) - shown} more' if len(dropped_poses) > shown else ''
    dropped = (f' ({len(dropped_poses)} poses dropped: {reasons}{more})'
               if dropped_poses else '')
    return (f'imu_to_camera needs at least {MIN_GRAVITY_POSES} poses with both a board view '
            f'and a still accelerometer reading 1 g, got {count}{dropped}: add poses')


def calibrate_directory(directory: str, board: Board, intrinsics_files: Sequence[str] = (),
                        accel_model: Optional[SensorModel] = None,
                        reference: Optional[str] = None,
                        estimate_tilt: bool = True) -> RigCalibration:
    """Calibrate the rig of ``directory`` (see the module docstring); raises AccelcalError."""
    start = time.perf_counter()
    dataset = scan_directory(directory, reference)
    detections, failed = _detect_all(dataset, board)
    intr = _intrinsics(dataset, board, detections, intrinsics_files)
    dropped_views: Dict[str, str] = {}
    for i, cam in enumerate(dataset.cameras):
        for pose, why in intr[i].dropped.items():
            dropped_views[f'{pose}/{cam}'] = f'intrinsics: {why}'
            detections.pop((pose, i), None)
    fit = fit_rig(detections, board.object_points(), [(x.K, x.D) for x in intr],
                  dataset.cameras, [x.source == 'board views' for x in intr])
    for (pose, i), why in fit.dropped.items():
        dropped_views[f'{pose}/{dataset.cameras[i]}'] = why
    gravity, dropped_poses = {}, {}
    for pose in dataset.poses:
        value, why = pose_gravity(os.path.join(directory, pose, 'imu.csv'), accel_model)
        if value is None:
            dropped_poses[pose] = why
        else:
            gravity[pose] = value
    usable = {p: fit.board_poses[p] for p in fit.board_poses if p in gravity}
    if len(usable) < MIN_GRAVITY_POSES:
        raise CalibrationError(_too_few_poses(len(usable), dropped_poses))
    mount = fit_imu_to_camera(usable, gravity, estimate_tilt)
    coverage = [coverage_fraction([c for (p, j), c in detections.items() if j == i],
                                  dataset.sizes[cam]) for i, cam in enumerate(dataset.cameras)]
    result = RigCalibration(board, dataset.cameras, [dataset.sizes[c] for c in dataset.cameras],
                            intr, fit, mount, gravity, detections, coverage, failed,
                            dropped_views, dropped_poses)
    result.warnings = _warnings(result)
    result.total_time_s = time.perf_counter() - start
    return result
