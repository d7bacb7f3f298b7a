"""Parameters of the ``stitcher`` node (pure: checked in tests without a ROS graph)."""
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


STITCHER_PARAMS = [
    ParamSpec('rig_file', '', 'rig YAML: cameras with name, width, height, K (9), D (5, '
              'optional), R = R_0i (9); camera 0 is the reference camera', read_only=True),
    ParamSpec('camera_topics', [], 'image topic of each rig camera, in rig order; empty: '
              '<camera name>/image_raw', kind='string_array', read_only=True),
    ParamSpec('fov_h_deg', 180.0, 'horizontal extent of the panorama sector', minimum=1.0,
              maximum=360.0, unit='deg', read_only=True),
    ParamSpec('fov_v_deg', 120.0, 'vertical extent of the panorama sector (at most 170 for '
              'cylindrical)', minimum=1.0, maximum=180.0, unit='deg', read_only=True),
    ParamSpec('width', 3600, 'panorama width', minimum=2, maximum=30000, unit='px',
              read_only=True),
    ParamSpec('height', 2400, 'panorama height', minimum=2, maximum=30000, unit='px',
              read_only=True),
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
    ParamSpec('compressed_output', False, 'also publish panorama/compressed '
              '(sensor_msgs/CompressedImage, JPEG) for viewers and recorders',
              read_only=True),
    ParamSpec('jpeg_quality', 80, 'JPEG quality of panorama/compressed', minimum=1,
              maximum=100),
    ParamSpec('frame_id', 'panorama', 'frame_id of the published panorama'),
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
              'more than this', minimum=0.0, maximum=10.0, unit='deg'),
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
