"""
Live capture of rig calibration poses (pure core of the ``rig_calibration`` node).

Camera frames (8-bit grey, stamp in s) and accelerometer samples (m/s^2, IMU frame) are
fed in. While the rig is still (:class:`accelcal_ros.sensor.stillness.StillnessDetector`)
for ``min_still_s``, the newest frame of every camera taken inside that still period is
searched for the board; when at least one camera sees it, a pose is written to
``directory/poseNN/<camera>.png`` plus ``imu.csv`` (the period's samples), the layout
``accelcal rig-calibrate`` reads, once per still period (or on :meth:`capture`).
:meth:`status` says per camera how many views and how much of the image they cover, per
pair how many shared views, and what to do next; :meth:`finish` calibrates the directory.
"""
from collections import deque
import os
from typing import Dict, List, Optional, Sequence, Tuple

from accelcal_ros.fileio import write_bytes_atomic
from accelcal_ros.rig.board import Board
from accelcal_ros.rig.calibrate import (calibrate_directory, MIN_SHARED_VIEWS,
                                        MIN_VIEWS_PER_CAMERA, RigCalibration)
from accelcal_ros.rig.detect import detect_board
from accelcal_ros.rig.intrinsics import coverage_fraction
from accelcal_ros.sensor.model import SensorModel
from accelcal_ros.sensor.recording import save_recording
from accelcal_ros.sensor.stillness import StillnessDetector, StillnessThresholds
import cv2
import numpy as np


class RigCapture:
    """Collects still poses with board views into a capture directory."""

    def __init__(self, directory: str, cameras: Sequence[str], board: Board,
                 auto: bool = True, min_still_s: float = 1.0,
                 thresholds: Optional[StillnessThresholds] = None,
                 imu_buffer_s: float = 30.0) -> None:
        """Start with no pose; existing ``poseNN`` folders in ``directory`` are kept."""
        self.directory = directory
        self.cameras = list(cameras)
        self.board = board
        self.auto = auto
        self.min_still_s = float(min_still_s)
        self._detector = StillnessDetector(thresholds, accel_unit_m_s2=1.0)
        self._imu: deque = deque()
        self._imu_buffer_s = float(imu_buffer_s)
        self._frames: Dict[str, Tuple[float, np.ndarray]] = {}
        self._searched: Dict[str, float] = {}
        self._captured_segment: Optional[float] = None
        self.views: Dict[str, List[np.ndarray]] = {c: [] for c in self.cameras}
        self.poses: List[Tuple[str, Tuple[str, ...]]] = []
        os.makedirs(directory, exist_ok=True)
        self._next = len([d for d in os.listdir(directory) if d.startswith('pose')])

    # -- input ----------------------------------------------------------------------
    def restart_clock(self) -> None:
        """
        Forget the samples and frames of before a jump back in time (a bag played again).

        Kept, they were written first into the next pose's ``imu.csv`` (times not
        increasing: the whole calibration then failed to read it); captured poses stay.
        """
        self._detector = StillnessDetector(self._detector.thresholds, accel_unit_m_s2=1.0)
        self._imu.clear()
        self._frames.clear()
        self._searched.clear()
        self._captured_segment = None

    def add_imu(self, t_s: float, accel_m_s2: Sequence[float]) -> Optional[str]:
        """Feed one accelerometer sample; return the new pose's name if one was captured."""
        self._detector.add(t_s, accel_m_s2)
        self._detector.ended.clear()
        self._imu.append((float(t_s), np.asarray(accel_m_s2, dtype=float)))
        while self._imu and self._imu[0][0] < t_s - self._imu_buffer_s:
            self._imu.popleft()
        return self._maybe_capture() if self.auto else None

    def add_image(self, camera: str, t_s: float, grey: np.ndarray) -> None:
        """Feed one camera frame (8-bit grey); unknown cameras are ignored."""
        if camera in self.views:
            self._frames[camera] = (float(t_s), grey)

    # -- capture --------------------------------------------------------------------
    def _segment(self):
        seg = self._detector.segment if self._detector.still else None
        return seg if seg is not None and seg.blocks else None

    def _frames_in(self, t0: float) -> Dict[str, Tuple[float, np.ndarray]]:
        return {c: f for c, f in self._frames.items() if f[0] >= t0}

    def _maybe_capture(self) -> Optional[str]:
        seg = self._segment()
        if seg is None or seg.duration_s < self.min_still_s:
            return None
        if self._captured_segment == seg.t_start_s:
            return None
        frames = self._frames_in(seg.t_start_s)
        fresh = {c: f for c, f in frames.items() if self._searched.get(c) != f[0]}
        if not fresh:
            return None
        for c, f in fresh.items():
            self._searched[c] = f[0]
        name, _ = self._save(seg.t_start_s, frames)
        if name:
            self._captured_segment = seg.t_start_s
        return name

    def capture(self) -> Tuple[bool, str]:
        """Capture now (the ``capture`` service): needs a still rig and a board in view."""
        seg = self._segment()
        if seg is None:
            return False, 'the rig is moving: hold it still, then capture'
        frames = self._frames_in(seg.t_start_s)
        if not frames:
            return False, 'no camera frame since the rig came to rest: wait for the cameras'
        name, seen = self._save(seg.t_start_s, frames)
        if not name:
            return False, f'no camera sees the whole {self.board.cols}x{self.board.rows} board'
        self._captured_segment = seg.t_start_s
        return True, f'captured {name}: board seen by {", ".join(seen)}'

    def _save(self, t0: float, frames: Dict[str, Tuple[float, np.ndarray]]):
        found = {}
        for cam, (_, grey) in frames.items():
            hit = detect_board(grey, self.board)
            if hit is not None:
                found[cam] = hit.corners
        if not found:
            return None, ()
        name = f'pose{self._next:02d}'
        folder = os.path.join(self.directory, name)
        for cam, (_, grey) in frames.items():
            ok, png = cv2.imencode('.png', grey)
            write_bytes_atomic(os.path.join(folder, f'{cam}.png'), png.tobytes())
        samples = [(t, a) for t, a in self._imu if t >= t0]
        save_recording(os.path.join(folder, 'imu.csv'), np.array([t for t, _ in samples]),
                       np.array([a for _, a in samples]).reshape(-1, 3))
        self._next += 1
        for cam, corners in found.items():
            self.views[cam].append(corners)
        seen = tuple(sorted(found))
        self.poses.append((name, seen))
        return name, seen

    # -- status and finish ----------------------------------------------------------
    def status(self) -> dict:
        """Per camera views and coverage, per pair shared views, and the next step."""
        cams = {}
        for cam in self.cameras:
            shape = self._frames[cam][1].shape if cam in self._frames else None
            size = (shape[1], shape[0]) if shape is not None else None
            cams[cam] = {'views': len(self.views[cam]),
                         'coverage': round(coverage_fraction(self.views[cam], size), 3)
                         if size and self.views[cam] else 0.0}
        pairs = {}
        for i, a in enumerate(self.cameras):
            for b in self.cameras[i + 1:]:
                pairs[f'{a}-{b}'] = sum(1 for _, seen in self.poses if a in seen and b in seen)
        todo = [f'show {c} the board (it has {v["views"]} views, needs '
                f'{MIN_VIEWS_PER_CAMERA})' for c, v in cams.items()
                if v['views'] < MIN_VIEWS_PER_CAMERA]
        todo += [f'move the board into its image corners for {c} (covers '
                 f'{100 * v["coverage"]:.0f} %)' for c, v in cams.items()
                 if v['views'] >= MIN_VIEWS_PER_CAMERA and v['coverage'] < 0.5]
        neighbours = [p for p, n in pairs.items() if 0 < n < MIN_SHARED_VIEWS]
        todo += [f'hold the board where {p.replace("-", " and ")} both see it'
                 for p in neighbours]
        if not todo and len(self.poses) < 12:
            todo.append('add poses turned about the vertical and tilted 20-40 deg')
        return {'poses': len(self.poses), 'still': self._detector.still, 'cameras': cams,
                'shared_views': pairs,
                'next': todo[0] if todo else 'enough poses: call rig_calibration/finish'}

    def finish(self, reference: Optional[str] = None, accel_model: Optional[SensorModel] = None
               ) -> RigCalibration:
        """Calibrate the capture directory (raises AccelcalError with what is missing)."""
        return calibrate_directory(self.directory, self.board, (), accel_model, reference)
