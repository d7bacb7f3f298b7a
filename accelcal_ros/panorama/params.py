"""Parameters of the ``stitcher`` node (pure: checked in tests without a ROS graph)."""
import math
from typing import Any, Optional, Tuple

from accelcal_ros.errors import InputError
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rotation_matrix_from_list
from accelcal_ros.panorama.projection import PROJECTIONS
from accelcal_ros.paramspec import ParamSpec


def _rotation_reason(values):
    try:
        rotation_matrix_from_list(values, 'imu_to_camera')
    except InputError as exc:
        return str(exc)
    return None


def _even(value):
    return None if value % 2 == 0 else 'must be even'


def _frame_id_reason(value: str) -> Optional[str]:
    """Return why ``value`` is not a frame id, or None (frame_tree loads scipy: on use)."""
    from accelcal_ros.frame_tree import frame_id_reason

    return frame_id_reason(value)


def _size_reason(value):
    return None if value == 0 or value >= 2 else 'must be 0 (from the rig) or at least 2'


MAX_PANORAMA_SIDE_PX = 30000


def _round_even(value: float) -> int:
    """Nearest even integer in [2, MAX_PANORAMA_SIDE_PX]."""
    return int(min(MAX_PANORAMA_SIDE_PX, max(2, 2 * round(value / 2.0))))


def reference_focal_px(rig: Any) -> float:
    """Focal length of the rig's reference camera (camera 0): ``(fx + fy) / 2``, pixels."""
    k = rig.cameras[0].K
    return (float(k[0][0]) + float(k[1][1])) / 2.0


def panorama_size_from_focal(focal_px: float, fov_h_deg: float, fov_v_deg: float,
                             projection: str = 'spherical') -> Tuple[int, int]:
    """
    Return the panorama ``(width, height)`` in pixels whose resolution is the camera's.

    A camera of focal length ``f`` (pixels) has ``f`` pixels per radian at its centre,
    ``f * pi / 180`` per degree; the panorama gets as many over its sector:
    ``width = fov_h_deg * f * pi / 180`` and, spherical, ``height = fov_v_deg * f * pi /
    180``; cylindrical (rows equal steps of ``tan(el)``), ``height = 2 f tan(fov_v / 2)``
    (``f`` rows per radian at the horizon). Each is rounded to the nearest even number
    and kept within [2, 30000]. E.g. f = 500 px over 180 x 120 deg: 1570 x 1048.
    """
    focal_px = float(focal_px)
    if not (math.isfinite(focal_px) and focal_px > 0):
        raise InputError("the reference camera's focal length must be a positive number "
                         f'of pixels, got {focal_px!r}: check K in the rig file')
    per_deg = focal_px * math.pi / 180.0
    width = _round_even(float(fov_h_deg) * per_deg)
    if projection == 'cylindrical':
        height = _round_even(2.0 * focal_px * math.tan(math.radians(float(fov_v_deg)) / 2.0))
    else:
        height = _round_even(float(fov_v_deg) * per_deg)
    return width, height


def panorama_size(rig: Any, width: int, height: int, fov_h_deg: float, fov_v_deg: float,
                  projection: str = 'spherical') -> Tuple[int, int, Optional[float]]:
    """
    Return ``(width, height, focal_px)``: the parameters, 0 replaced by the rig's rule.

    ``focal_px`` is the reference camera's focal length used
    (:func:`panorama_size_from_focal`), None when both sides were given.
    """
    if width and height:
        return int(width), int(height), None
    focal = reference_focal_px(rig)
    auto_w, auto_h = panorama_size_from_focal(focal, fov_h_deg, fov_v_deg, projection)
    return int(width) or auto_w, int(height) or auto_h, focal


_SIZE_RULE = ("0: from the rig, the reference camera's resolution over the sector "
              '(f px/rad = f*pi/180 px/deg, f = (fx + fy)/2 of camera 0; ')


STITCHER_PARAMS = [
    ParamSpec('rig_file', '', 'rig YAML: cameras with name, width, height, K (9), D (5, '
              'optional), R = R_0i (9); camera 0 is the reference camera', read_only=True),
    ParamSpec('camera_topics', [], 'image topic of each rig camera, in rig order; empty: '
              '<camera name>/image_raw', kind='string_array', read_only=True),
    ParamSpec('fov_h_deg', 180.0, 'horizontal extent of the panorama sector', minimum=1.0,
              maximum=360.0, unit='deg', read_only=True),
    ParamSpec('fov_v_deg', 120.0, 'vertical extent of the panorama sector (at most 170 for '
              'cylindrical)', minimum=1.0, maximum=180.0, unit='deg', read_only=True),
    ParamSpec('width', 0, 'panorama width; ' + _SIZE_RULE + 'width = fov_h_deg * f*pi/180, '
              'rounded to even: 1570 for f = 500 over 180 deg)', minimum=0, maximum=30000,
              unit='px', validator=_size_reason, read_only=True),
    ParamSpec('height', 0, 'panorama height; ' + _SIZE_RULE + 'height = fov_v_deg * '
              'f*pi/180 spherical, 2 f tan(fov_v/2) cylindrical, rounded to even)',
              minimum=0, maximum=30000, unit='px', validator=_size_reason, read_only=True),
    ParamSpec('projection', 'spherical', 'spherical (equal angle per pixel) or cylindrical',
              choices=PROJECTIONS, read_only=True),
    ParamSpec('imu_to_camera', [float(v) for v in DEFAULT_IMU_TO_CAMERA.reshape(-1)],
              'rotation taking IMU body vectors (x fwd, y left, z up) into the reference '
              "camera's optical frame (x right, y down, z fwd), 9 row-major values",
              lengths=(9,), validator=_rotation_reason, read_only=True),
    ParamSpec('output_encoding', 'bgr8', 'encoding of the published panorama (inputs in '
              'rgb8, bgr8 or mono8 are converted)', choices=('bgr8', 'rgb8', 'mono8'),
              read_only=True),
    ParamSpec('image_reliability', 'reliable', 'QoS reliability of the image '
              'subscriptions: reliable (default: every frame of a reliable camera driver '
              'arrives whole, however large) or best_effort (for best-effort publishers, '
              'which a reliable subscription does not receive from)',
              choices=('best_effort', 'reliable'), read_only=True),
    ParamSpec('image_queue_depth', 2, 'keep-last depth of each image subscription: the '
              'newest frames are kept, older ones dropped when the node falls behind (the '
              'publisher never waits for it)', minimum=1, maximum=100, read_only=True),
    ParamSpec('image_transport', 'raw', 'raw: subscribe each camera topic '
              '(sensor_msgs/Image); compressed: subscribe <topic>/compressed '
              "(sensor_msgs/CompressedImage, JPEG or PNG as image_transport's compressed "
              'plugin writes them), decoded in parallel off the executor; frames that do '
              'not decode are counted and skipped', choices=('raw', 'compressed'),
              read_only=True),
    ParamSpec('compressed_output', False, 'also publish panorama/compressed '
              '(sensor_msgs/CompressedImage, JPEG) for viewers and recorders',
              read_only=True),
    ParamSpec('jpeg_quality', 80, 'JPEG quality of panorama/compressed', minimum=1,
              maximum=100),
    ParamSpec('frame_id', 'panorama', 'frame_id of the published panorama (its views: '
              '<frame_id>_roi_<name>)', validator=_frame_id_reason),
    ParamSpec('camera_info_topics', [], 'one sensor_msgs/CameraInfo topic per camera (rig '
              'order): K and D from the camera drivers instead of the rig file (R_0i and '
              'imu_to_camera still from it); empty = those of the rig file', kind='string_array',
              read_only=True),
    ParamSpec('camera_info_timeout_s', 10.0, 'how long start-up waits for camera_info_topics',
              minimum=0.1, maximum=600.0, unit='s', read_only=True),
    ParamSpec('sync_tolerance_s', 0.02, 'frames of different cameras whose stamps differ by '
              'at most this are stitched together', minimum=0.0, maximum=10.0, unit='s'),
    ParamSpec('attitude_tolerance_s', 0.5, 'the attitude used is the one nearest the frame '
              'stamp within this; otherwise the frame set is skipped', minimum=0.0,
              maximum=60.0, unit='s'),
    ParamSpec('attitude_wait_s', 0.05, 'when no attitude stamped at or after the frames has '
              'arrived yet, wait this long for one before using the nearest', minimum=0.0,
              maximum=5.0, unit='s'),
    ParamSpec('stale_timeout_s', 1.0, 'a camera silent for longer is stalled: its sector '
              'stays black and /diagnostics reports it', minimum=0.05, maximum=60.0,
              unit='s'),
    ParamSpec('time_jump_threshold_s', 2.0, 'a stream whose stamp moves this much more (or '
              'less) than the wall time since its previous message has jumped (a bag '
              'replayed in a loop, a clock set): buffered frames are dropped and stitching '
              'starts again, logged and counted in /diagnostics', minimum=0.1,
              maximum=3600.0, unit='s', read_only=True),
    ParamSpec('rebuild_threshold_deg', 0.01, 'the lookup is rebuilt when the tilt moves by '
              'more than this (0.01: 0.1 px of a panorama of f = 550 px/rad)', minimum=0.0,
              maximum=10.0, unit='deg'),
    ParamSpec('grid_step', 20, 'cell size of the fast lookup rebuild (even; the largest '
              'even divisor of width not above it is used)', minimum=4, maximum=128,
              unit='px', validator=_even, read_only=True),
    ParamSpec('blend_width_deg', 0.0, 'feathered blending band at the seams (0: off, as '
              'in paper A; > 0 builds exact maps, slow to rebuild)', minimum=0.0,
              maximum=90.0, unit='deg', read_only=True),
    ParamSpec('threads', 2, 'OpenCV worker threads (0: OpenCV default)', minimum=0,
              maximum=64, read_only=True),
    ParamSpec('pipeline', True, 'remap each frame in a render thread while the lookup of '
              'the next frame set is rebuilt (two mosaics and lookups: about twice the '
              'memory, about 80 MB more at 3600x2400); false: one frame after the other',
              read_only=True),
]
"""Every parameter of the ``stitcher`` node with its default (see config/stitcher.yaml)."""
