"""
The capture directory: ``DIR/poseNN/<camera>.png`` and ``DIR/poseNN/imu.csv``.

Each pose folder holds one image per camera (the camera's name is the file name without
``.png``) and the accelerometer log of that still pose (``t,ax,ay,az``, s and m/s^2,
read by :func:`accelcal_ros.sensor.recording.load_recording`). The reference camera is
the first name in sorted order unless one is named. Images are read as 8-bit grey; all
images of one camera must have one size.
"""
from dataclasses import dataclass, field
import os
from typing import Dict, List, Optional, Tuple

from accelcal_ros.errors import FileFormatError, InputError
from accelcal_ros.fileio import read_image_file
from accelcal_ros.sensor.model import SensorModel
from accelcal_ros.sensor.recording import load_recording
from accelcal_ros.sensor.stillness import still_segments, StillnessThresholds
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
import cv2
import numpy as np

GRAVITY_BAND_RAW_G = (0.7, 1.3)
"""Mean still magnitude (g) an uncalibrated log must read to be gravity: a raw ADXL345 reads
0.85-1.15 g at rest (field scales 0.8-1.2, biases of a few 0.01 g; paper A's K100 reads
0.81 g on one axis); outside, the log is not gravity alone (a zero or stuck reading, free
fall, a lasting acceleration) and its direction would pull ``imu_to_camera`` away."""
GRAVITY_BAND_CALIBRATED_G = (0.9, 1.1)
"""The same with a calibration: a fitting calibration brings a still reading within
:data:`accelcal_ros.sensor.model.GRAVITY_FIT_TOLERANCE_G` (0.03 g) of 1 g; 0.1 g off (over
three times that, a direction error of up to asin(0.1) = 5.7 deg) is not gravity alone, or
the calibration is of another sensor."""
MAX_READING_M_S2 = 1000.0 * STANDARD_GRAVITY_M_S2
"""A sample above this (1000 g; the ADXL345 reads at most 16 g) is corrupt, not a force: the
pose is dropped before any arithmetic that could overflow on it (1e300)."""


@dataclass
class Dataset:
    """Pose names, camera names (reference first), image paths and sizes per camera."""

    directory: str
    poses: List[str]
    cameras: List[str]
    images: Dict[Tuple[str, str], str]
    sizes: Dict[str, Tuple[int, int]] = field(default_factory=dict)

    def image_path(self, pose: str, camera: str) -> Optional[str]:
        """Return the image of ``camera`` in ``pose`` or None when there is none."""
        return self.images.get((pose, camera))


def scan_directory(directory: str, reference: Optional[str] = None) -> Dataset:
    """List the pose folders and cameras of ``directory``; check every pose has imu.csv."""
    if not os.path.isdir(directory):
        raise FileFormatError(directory, 'not a directory (expected DIR/poseNN/<camera>.png '
                              'and DIR/poseNN/imu.csv)')
    poses, images, cameras = [], {}, set()
    for name in sorted(os.listdir(directory)):
        folder = os.path.join(directory, name)
        if not os.path.isdir(folder):
            continue
        pngs = sorted(f for f in os.listdir(folder) if f.lower().endswith('.png'))
        if not pngs:
            continue
        poses.append(name)
        for png in pngs:
            cam = png[:-4]
            cameras.add(cam)
            images[(name, cam)] = os.path.join(folder, png)
    if not poses:
        raise FileFormatError(directory, 'holds no pose folder with images (expected '
                              'DIR/poseNN/<camera>.png and DIR/poseNN/imu.csv)')
    missing = [p for p in poses if not os.path.exists(os.path.join(directory, p, 'imu.csv'))]
    if missing:
        raise FileFormatError(os.path.join(directory, missing[0], 'imu.csv'),
                              f'missing: every pose needs the accelerometer log of the still '
                              f'rig (t,ax,ay,az); missing in {", ".join(missing)}')
    names = sorted(cameras)
    if reference is not None:
        if reference not in names:
            raise InputError(f'--reference {reference!r} is not a camera of {directory}; '
                             f'cameras: {", ".join(names)}')
        names.remove(reference)
        names.insert(0, reference)
    return Dataset(directory, poses, names, images)


def read_grey(path: str) -> np.ndarray:
    """Read an image as 8-bit grey; FileFormatError if it cannot be decoded."""
    image = read_image_file(path, cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise FileFormatError(path, 'cannot be read as an image (corrupt or not a PNG)')
    return image


def check_size(dataset: Dataset, camera: str, pose: str, image: np.ndarray) -> None:
    """Record the camera's image size; InputError if it differs from its earlier images."""
    size = (int(image.shape[1]), int(image.shape[0]))
    first = dataset.sizes.setdefault(camera, size)
    if first != size:
        first_pose = next(p for p in dataset.poses if (p, camera) in dataset.images)
        raise InputError(f'camera {camera}: images of different sizes ({first_pose}: '
                         f'{first[0]}x{first[1]}, {pose}: {size[0]}x{size[1]}); one camera '
                         'must keep one resolution')


def pose_gravity(path: str, model: Optional[SensorModel] = None,
                 thresholds: Optional[StillnessThresholds] = None
                 ) -> Tuple[Optional[np.ndarray], str]:
    """
    Return ``(mean specific force (m/s^2, IMU frame), '')`` of a still log, or ``(None, why)``.

    With an accelerometer ``model`` (``correct(raw_g) -> f_g``) the samples are corrected
    first. The log is still when one still segment (:mod:`accelcal_ros.sensor.stillness`)
    covers at least half of it; its mean must read 1 g (:data:`GRAVITY_BAND_RAW_G`, with a
    model other than the identity :data:`GRAVITY_BAND_CALIBRATED_G`) and no sample may exceed
    :data:`MAX_READING_M_S2`, else the pose is dropped with the reason.
    """
    t, accel = load_recording(path)
    duration = float(t[-1] - t[0]) if t.size > 1 else 0.0
    if t.size < 3 or duration <= 0:
        return None, f'{path}: too short ({t.size} samples); log the still rig for ~1 s'
    largest = np.abs(accel).max(axis=1)
    corrupt = np.flatnonzero(largest > MAX_READING_M_S2)
    if corrupt.size:
        k = int(corrupt[0])
        return None, (f'corrupt accelerometer log: sample {k + 1} reads {largest[k]:.3g} m/s^2 '
                      f'({corrupt.size} of {t.size} samples above {MAX_READING_M_S2:.0f} '
                      'm/s^2, more than any accelerometer measures)')
    if model is not None:
        accel = np.asarray(model.correct(accel / STANDARD_GRAVITY_M_S2)) * STANDARD_GRAVITY_M_S2
    segments = still_segments(t, accel, thresholds=thresholds, accel_unit_m_s2=1.0,
                              min_still_s=0.5 * duration)
    if not segments:
        spread = float(np.max(np.std(accel, axis=0)))
        return None, (f'the IMU moved (accelerometer spread {spread:.2f} m/s^2 over '
                      f'{duration:.1f} s): hold the rig still while the pose is taken')
    best = max(segments, key=lambda s: s.samples)
    mean = np.asarray(best.accel_mean, dtype=float)
    magnitude_g = float(np.linalg.norm(mean)) / STANDARD_GRAVITY_M_S2
    calibrated = model is not None and not model.is_identity()
    low, high = GRAVITY_BAND_CALIBRATED_G if calibrated else GRAVITY_BAND_RAW_G
    if not low <= magnitude_g <= high:
        after = ' after the calibration' if calibrated else ' (uncalibrated)'
        other = ', or a calibration of another sensor' if calibrated else ''
        return None, (f'the accelerometer reads {magnitude_g:.3f} g{after}, not gravity (a '
                      f'still pose reads {low:g}..{high:g} g): a zero or stuck sensor, an '
                      f'acceleration{other}')
    return mean, ''
