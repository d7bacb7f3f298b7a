"""Parameters of the ``p2p`` node (pure: specifications and their validation)."""
from typing import Optional, Sequence

from accelcal_ros.errors import InputError
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rotation_matrix_from_list
from accelcal_ros.p2p.beacons import ORDERS
from accelcal_ros.p2p.solver import MAX_COORDINATE_M
from accelcal_ros.paramspec import ParamSpec
import numpy as np


def emitters_reason(values: Sequence[float]) -> Optional[str]:
    """
    Return why 6 emitter coordinates are unusable, or None.

    Usable: finite, within +-``MAX_COORDINATE_M`` (m), distinct, not on one vertical line.
    """
    if len(values) != 6:
        return f'expected 6 values (M1 x y z, M2 x y z in m), got {len(values)}'
    m = np.asarray(values, dtype=float).reshape(2, 3)
    if not np.all(np.isfinite(m)):
        return 'coordinates must be finite numbers (m)'
    if np.abs(m).max() > MAX_COORDINATE_M:
        return (f'coordinates must be within +-{MAX_COORDINATE_M:,.0f} m (emitters in metres '
                'in a local object frame)')
    delta = m[0] - m[1]
    baseline = float(np.linalg.norm(delta))
    if baseline == 0.0:
        return 'M1 and M2 coincide: give two distinct points'
    if np.hypot(delta[0], delta[1]) <= 1e-6 * baseline:
        return 'M1 and M2 lie on one vertical line (object z is up): yaw would be unobservable'
    return None


def rotation_reason(values: Sequence[float]) -> Optional[str]:
    """Return why 9 values are not a rotation matrix, or None."""
    try:
        rotation_matrix_from_list(values, 'imu_to_camera')
    except InputError as exc:
        return str(exc)
    return None


P2P_PARAMS = (
    ParamSpec('emitters', [0.0, 0.0, 0.0, 1.0, 0.0, 0.0], 'Object coordinates of emitters M1 '
              'and M2: x1, y1, z1, x2, y2, z2 (object frame, z up, m; each within +-1e6). Not on '
              'one vertical line; M1 is the emitter `order` picks first.', lengths=(6,),
              validator=emitters_reason, unit='m'),
    ParamSpec('imu_to_camera', [float(v) for v in DEFAULT_IMU_TO_CAMERA.reshape(-1)],
              'Rotation from the IMU body frame (REP-103, x fwd, y left, z up) to the camera '
              'optical frame (x right, y down, z fwd), 9 row-major values; default: camera '
              'looking along body +x.', lengths=(9,), validator=rotation_reason),
    ParamSpec('threshold', 160, 'Grey level above which a pixel may belong to an emitter '
              '(8-bit; colour images are converted to grey).', minimum=0, maximum=254),
    ParamSpec('min_area_px', 2, 'Smallest emitter blob, in pixels.', minimum=1,
              maximum=1000000, unit='px'),
    ParamSpec('max_area_px', 5000, 'Largest emitter blob, in pixels.', minimum=1,
              maximum=10000000, unit='px'),
    ParamSpec('min_peak', 0, 'Brightest pixel a blob must reach (0: no limit).', minimum=0,
              maximum=255),
    ParamSpec('max_candidates', 50, 'Stop looking beyond this many blobs within the limits '
              '(a bright background; raise the threshold).', minimum=2, maximum=100000),
    ParamSpec('order', 'left_to_right', 'Which blob is M1: left_to_right (M1 is the left '
              'emitter as seen by the camera, judged against the horizon), right_to_left, '
              'top_to_bottom, bottom_to_top, larger_first, smaller_first, brighter_first, '
              'dimmer_first.', choices=ORDERS),
    ParamSpec('attitude_tolerance_s', 0.05, 'Largest stamp difference between an image and '
              'the attitude used for it.', minimum=0.0, maximum=10.0, unit='s'),
    ParamSpec('continuity_max_age_s', 1.0, 'Two valid solutions: take the one nearer the '
              'last pose if that is at most this old (stamp time); otherwise report the '
              'ambiguity and publish no pose (0: never).', minimum=0.0, maximum=3600.0,
              unit='s'),
    ParamSpec('image_qos', 'reliable', 'QoS of the image subscription: reliable (default, '
              'keep-last 2: every frame of a reliable camera driver arrives whole, however '
              'large; a slow node only drops older frames) or sensor_data (best effort, '
              'depth 5: for best-effort drivers, which a reliable subscription does not '
              'receive from).', choices=('sensor_data', 'reliable'), read_only=True),
    ParamSpec('image_transport', 'raw', 'raw: subscribe image (sensor_msgs/Image); '
              'compressed: subscribe image/compressed (sensor_msgs/CompressedImage, JPEG or '
              "PNG as image_transport's compressed plugin writes them), decoded off the "
              'executor thread; frames that do not decode are counted and skipped.',
              choices=('raw', 'compressed'), read_only=True),
    ParamSpec('diagnostics_period_s', 1.0, 'Period of /diagnostics messages.', minimum=0.1,
              maximum=60.0, unit='s'),
)
"""Every parameter of the ``p2p`` node with its default, description and range."""
