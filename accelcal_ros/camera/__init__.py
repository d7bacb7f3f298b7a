"""
The camera model every feature shares (pure core: numpy, OpenCV in tests only).

:class:`CameraModel` holds the intrinsics (``K``, image size) and the lens distortion
(OpenCV ``plumb_bob``/``rational_polynomial`` or fisheye ``equidistant``), with
vectorised :meth:`~CameraModel.project` / :meth:`~CameraModel.unproject` in the optical
frame (z forward, x right, y down) and OpenCV's pixel convention; see
:mod:`accelcal_ros.camera.model` and :mod:`accelcal_ros.camera.distortion`.
"""
from accelcal_ros.camera.distortion import (distort_normalized, DISTORTION_MODELS, EQUIDISTANT,
                                            PLUMB_BOB, RATIONAL_POLYNOMIAL,
                                            undistort_normalized)
from accelcal_ros.camera.model import (CAMERA_KEYS, camera_model_from_mapping, CameraModel,
                                       ROS_CALIBRATION_KEYS)

__all__ = ['CAMERA_KEYS', 'CameraModel', 'camera_model_from_mapping', 'distort_normalized',
           'DISTORTION_MODELS', 'EQUIDISTANT', 'PLUMB_BOB', 'RATIONAL_POLYNOMIAL',
           'ROS_CALIBRATION_KEYS', 'undistort_normalized']
