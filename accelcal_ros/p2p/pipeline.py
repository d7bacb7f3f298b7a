"""
The ``p2p`` node's logic without ROS: camera info, attitude matching, detection, solve.

:class:`P2PPipeline` receives camera calibrations, attitudes (REP-103 roll/pitch of the
IMU, rad, with stamps in seconds) and grey images with stamps, and returns one
:class:`FrameResult` per image: a pose, or the reason there is none. Attitudes are
matched to images by stamp (:class:`~accelcal_ros.rosutil.stamp_sync.StampMatcher`,
nearest within ``attitude_tolerance_s``); an image that arrives before its attitude
waits (the newest one only) until the attitude stream passes its stamp. Two valid
solutions are resolved by continuity with the last pose when that is recent enough,
otherwise reported.
"""
from dataclasses import dataclass, field
from typing import Any, List, Mapping, Optional, Sequence, Tuple

from accelcal_ros.camera import CameraModel
from accelcal_ros.errors import AccelcalError
from accelcal_ros.frames import check_attitude, rotation_matrix_from_list
from accelcal_ros.p2p.beacons import BeaconDetection, detect_beacons, DetectorSettings
from accelcal_ros.p2p.solver import down_from_roll_pitch, P2PSolution, solve
from accelcal_ros.rosutil.stamp_sync import StampMatcher
import numpy as np

MAX_WAIT_S = 1.0
"""An image waits for its attitude only if the attitude stream is less than this behind."""


@dataclass
class FrameResult:
    """
    Outcome of one image.

    ``solution`` (a :class:`~accelcal_ros.p2p.solver.P2PSolution`) or ``None`` with
    ``reason``; ``candidates``: every valid solution; ``detection``: the
    :class:`~accelcal_ros.p2p.beacons.BeaconDetection` (None if not run); ``tag``: what
    the caller passed with the image (the node passes the image header); ``dropped``:
    the kind of a dropped image ('' when the image was used, even with no pose): an
    image no camera_info fits (``images_size``), one without an attitude near its stamp
    (``images_no_attitude``).
    """

    stamp_s: float
    frame_id: str
    solution: Optional[P2PSolution] = None
    reason: str = ''
    candidates: List[P2PSolution] = field(default_factory=list)
    detection: Optional[BeaconDetection] = None
    attitude: Optional[Tuple[float, float]] = None
    resolved_by_continuity: bool = False
    tag: Any = None
    dropped: str = ''


class P2PPipeline:
    """Stateful P2P positioning from images, camera info and attitude (see the module text)."""

    def __init__(self, values: Mapping[str, Any]) -> None:
        self.values = dict(values)
        self.camera: Optional[CameraModel] = None
        self.camera_reason = 'no camera_info received yet'
        self.attitudes = StampMatcher(['attitude'], depth=400)
        self.pending: Optional[Tuple[float, str, np.ndarray, Any]] = None
        self.last_pose: Optional[Tuple[float, P2PSolution]] = None
        self.configure(self.values)

    def configure(self, values: Mapping[str, Any]) -> None:
        """Apply (validated) parameter values; InputError if the set is inconsistent."""
        from accelcal_ros.errors import InputError

        merged = dict(self.values, **values)
        settings = DetectorSettings(
            threshold=merged['threshold'], min_area_px=merged['min_area_px'],
            max_area_px=merged['max_area_px'], min_peak=merged['min_peak'],
            max_candidates=merged['max_candidates'], order=merged['order'])
        mount = rotation_matrix_from_list(merged['imu_to_camera'], 'imu_to_camera')
        points = np.asarray(merged['emitters'], dtype=float).reshape(2, 3)
        if not np.all(np.isfinite(points)):
            raise InputError('emitters contain NaN or infinity')
        self.values, self.settings, self.mount, self.points = merged, settings, mount, points

    def set_camera_info(self, k: Sequence[float], d: Sequence[float], distortion_model: str,
                        width: int, height: int) -> Optional[str]:
        """Store the camera calibration; returns None or the reason it was rejected."""
        try:
            self.camera = CameraModel.from_camera_info(k, d, distortion_model, width, height)
            self.camera_reason = ''
        except AccelcalError as exc:
            self.camera = None
            self.camera_reason = f'camera_info rejected: {exc}'
        return self.camera_reason or None

    def add_attitude(self, stamp_s: float, roll: float, pitch: float) -> List[FrameResult]:
        """
        Store an attitude; return the results of images that were waiting for it.

        An attitude that is not one (not finite, roll beyond +-pi, pitch beyond +-pi/2:
        :func:`~accelcal_ros.frames.attitude_problem`) raises :class:`InputError` and is
        not stored.
        """
        roll, pitch = check_attitude(roll, pitch, f'attitude at {stamp_s:.3f} s')
        self.attitudes.add('attitude', stamp_s, (roll, pitch))
        if self.pending is None:
            return []
        image_stamp = self.pending[0]
        if (self._matched(image_stamp) is not None
                or stamp_s > image_stamp + self.values['attitude_tolerance_s']):
            pending, self.pending = self.pending, None
            return [self._process(*pending)]
        return []

    def _matched(self, stamp_s: float) -> Optional[Tuple[float, float]]:
        hit = self.attitudes.nearest(stamp_s, self.values['attitude_tolerance_s'])['attitude']
        return None if hit is None else hit[1]

    def add_image(self, stamp_s: float, frame_id: str, grey: np.ndarray,
                  tag: Any = None) -> List[FrameResult]:
        """
        Process an image (grey uint8) or hold it until its attitude arrives.

        Returns the list of finished :class:`FrameResult` (possibly empty while waiting,
        or two when a newer image displaces an older waiting one).
        """
        results: List[FrameResult] = []
        if self.pending is not None:
            results.append(self._process(*self.pending))
            self.pending = None
        latest = self.attitudes.latest_stamp()
        tolerance = self.values['attitude_tolerance_s']
        if (self.camera is not None and latest is not None and self._matched(stamp_s) is None
                and stamp_s - MAX_WAIT_S < latest < stamp_s + tolerance):
            self.pending = (stamp_s, frame_id, grey, tag)
            return results
        results.append(self._process(stamp_s, frame_id, grey, tag))
        return results

    def _process(self, stamp_s: float, frame_id: str, grey: np.ndarray,
                 tag: Any = None) -> FrameResult:
        result = FrameResult(stamp_s, frame_id, tag=tag)
        if self.camera is None:
            result.reason = self.camera_reason
            return result
        cam = self.camera
        if cam.width and cam.height and grey.shape[:2] != (cam.height, cam.width):
            result.reason = (f'image {grey.shape[1]}x{grey.shape[0]} does not match '
                             f'camera_info {cam.width}x{cam.height}')
            result.dropped = 'images_size'
            return result
        latest = self.attitudes.latest_stamp()
        attitude = self._matched(stamp_s)
        if attitude is None:
            if latest is None:
                result.reason = 'no attitude received yet (topic attitude)'
            else:
                nearest = self.attitudes.nearest(stamp_s, float('inf'))['attitude'][0]
                result.reason = (f'no attitude within {self.values["attitude_tolerance_s"]:g} '
                                 f's of the image stamp (nearest {nearest - stamp_s:+.3f} s '
                                 f'away): attitude messages dropped, or the camera and IMU '
                                 f'clocks differ')
                result.dropped = 'images_no_attitude'
            return result
        result.attitude = attitude
        if not np.all(np.isfinite(attitude)):
            result.reason = 'attitude contains NaN or infinity (IMU not ready?)'
            return result
        down = down_from_roll_pitch(attitude[0], attitude[1], self.mount)
        try:
            detection = detect_beacons(grey, self.settings, cam, down)
        except AccelcalError as exc:
            result.reason = f'detection failed: {exc}'
            return result
        result.detection = detection
        if not detection.ok or detection.rays is None:
            result.reason = detection.reason or 'no rays (no camera matrix)'
            return result
        try:
            candidates = solve(detection.rays, self.points, down)
        except AccelcalError as exc:
            result.reason = f'no pose: {exc}'
            return result
        result.candidates = candidates
        if len(candidates) == 1:
            result.solution = candidates[0]
        else:
            last = self.last_pose
            max_age = self.values['continuity_max_age_s']
            if last is not None and max_age > 0 and abs(stamp_s - last[0]) <= max_age:
                result.solution = min(candidates, key=lambda s: _pose_distance(s, last[1]))
                result.resolved_by_continuity = True
            else:
                ranges = ', '.join(f'{s.range_m:.3f} m / yaw {np.degrees(s.yaw):.1f} deg'
                                   for s in candidates)
                result.reason = (f'ambiguous: two valid solutions ({ranges}) and no pose '
                                 f'within {max_age:g} s to choose by continuity')
                return result
        if result.solution is not None:
            self.last_pose = (stamp_s, result.solution)
        return result


def _pose_distance(solution: P2PSolution, reference: P2PSolution) -> float:
    """Return a unitless distance between two poses (relative translation + rotation angle)."""
    scale = max(float(np.linalg.norm(reference.translation)), 1e-9)
    dt = float(np.linalg.norm(solution.translation - reference.translation)) / scale
    cos_angle = (np.trace(solution.rotation @ reference.rotation.T) - 1.0) / 2.0
    return dt + float(np.arccos(np.clip(cos_angle, -1.0, 1.0)))
