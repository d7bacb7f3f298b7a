"""
Deserialised bag messages (rosbags classes, ROS 1 or ROS 2) -> numpy.

The field names are the ROS message definitions', so these functions work on rosbags'
classes as on rclpy's. Units stay ROS's (REP-103: m, m/s^2, rad/s, rad).

- sensor_msgs/Imu: :func:`imu_values` (specific force m/s^2, rate rad/s, whether the rate
  is provided: REP-145 ``angular_velocity_covariance[0] == -1`` means it is not);
- sensor_msgs/PointCloud2: :func:`cloud_array` (structured array, every field kept;
  :func:`accelcal_ros.rosutil.pointcloud2.pointcloud2_to_array`, pure numpy);
- nav_msgs/Odometry: :func:`odometry_pose` (position m and quaternion x y z w of the child
  frame in the parent frame);
- sensor_msgs/Image and CompressedImage: :func:`image_array` (OpenCV order, BGR);
- geometry_msgs/Vector3Stamped from the attitude node: :func:`attitude_roll_pitch`
  (x = roll, y = pitch, rad);
- sensor_msgs/CameraInfo: :func:`camera_info` (K, D, P, size, distortion model);
- sensor_msgs/NavSatFix: :func:`navsat_fix` (WGS84 lat/lon deg, altitude m, status);
  sensor_msgs/Imu's orientation: :func:`imu_orientation`.
"""
from typing import Any, Dict, Optional, Sequence, Tuple

from accelcal_ros.errors import InputError
import numpy as np

IMU = 'sensor_msgs/Imu'
POINTCLOUD2 = 'sensor_msgs/PointCloud2'
ODOMETRY = 'nav_msgs/Odometry'
IMAGE = 'sensor_msgs/Image'
COMPRESSED_IMAGE = 'sensor_msgs/CompressedImage'
VECTOR3_STAMPED = 'geometry_msgs/Vector3Stamped'
CAMERA_INFO = 'sensor_msgs/CameraInfo'
NAVSATFIX = 'sensor_msgs/NavSatFix'
NAVSAT_NO_FIX = -1
"""sensor_msgs/NavSatStatus ``STATUS_NO_FIX``."""


def imu_values(msg: Any) -> Tuple[np.ndarray, np.ndarray, bool]:
    """Return ``(specific force (3,) m/s^2, angular rate (3,) rad/s, rate provided)``."""
    a, w = msg.linear_acceleration, msg.angular_velocity
    accel = np.array([a.x, a.y, a.z], dtype=float)
    gyro = np.array([w.x, w.y, w.z], dtype=float)
    provided = float(msg.angular_velocity_covariance[0]) != -1.0
    return accel, gyro, provided


def cloud_array(msg: Any) -> np.ndarray:
    """Return the points of a PointCloud2 as a packed structured array (fields kept)."""
    from accelcal_ros.rosutil.pointcloud2 import pointcloud2_to_array

    return pointcloud2_to_array(msg)


def odometry_pose(msg: Any) -> Tuple[np.ndarray, np.ndarray]:
    """Return ``(position (3,) m, quaternion (4,) x y z w)`` of an Odometry's pose."""
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    return (np.array([p.x, p.y, p.z], dtype=float),
            np.array([q.x, q.y, q.z, q.w], dtype=float))


def attitude_roll_pitch(msg: Any) -> Tuple[float, float]:
    """Return ``(roll, pitch)`` rad of the attitude node's Vector3Stamped (x, y)."""
    return float(msg.vector.x), float(msg.vector.y)


def image_array(msg: Any, msgtype: str = IMAGE) -> np.ndarray:
    """Return an Image or CompressedImage as an OpenCV BGR (or mono) uint8 array."""
    if msgtype == COMPRESSED_IMAGE:
        import cv2

        data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
        img = cv2.imdecode(data, cv2.IMREAD_COLOR) if data.size else None
        if img is None:
            raise InputError(f'CompressedImage ({msg.format!r}) cannot be decoded')
        return img
    from accelcal_ros.rosutil.images import image_msg_to_array

    enc = str(msg.encoding).lower()
    return image_msg_to_array(msg, want=None if enc.startswith('mono') else 'bgr8',
                              encodings=('rgb8', 'bgr8', 'mono8', 'mono16'))


def camera_info(msg: Any) -> Dict[str, Any]:
    """Return ``{'K' (3, 3), 'D' (n,), 'P' (3, 4), 'width', 'height', 'distortion_model'}``."""
    k = np.asarray(getattr(msg, 'k', getattr(msg, 'K', None)), dtype=float).reshape(3, 3)
    d = np.asarray(getattr(msg, 'd', getattr(msg, 'D', ())), dtype=float).reshape(-1)
    p = np.asarray(getattr(msg, 'p', getattr(msg, 'P', None)), dtype=float).reshape(3, 4)
    if not (np.all(np.isfinite(k)) and k[0, 0] > 0 and k[1, 1] > 0):
        raise InputError(f'CameraInfo has no valid K (focal lengths {k[0, 0]}, {k[1, 1]})')
    return {'K': k, 'D': d, 'P': p, 'width': int(msg.width), 'height': int(msg.height),
            'distortion_model': str(msg.distortion_model)}


def imu_arrays_from_raw(raws: Sequence[bytes], ros1: bool) -> Optional[dict]:
    """
    Decode serialised sensor_msgs/Imu messages of one layout at once (vectorised).

    ROS 2 CDR (little endian; 4-byte encapsulation, ``float64`` aligned to 8 from the
    payload start) or ROS 1 (packed, ``seq`` first). Returns ``{'header_ns', 'frame_id',
    'accel', 'gyro', 'gyro_provided'}`` (arrays per message), or None when the messages do
    not share one length and frame_id or are big-endian: the caller then deserialises
    them one by one.
    """
    n = len(raws)
    if n == 0:
        return None
    size = len(raws[0])
    if any(len(r) != size for r in raws):
        return None
    buf = np.frombuffer(b''.join(raws), dtype=np.uint8).reshape(n, size)

    def column(offset: int, dtype: str) -> np.ndarray:
        width = np.dtype(dtype).itemsize
        return np.ascontiguousarray(buf[:, offset:offset + width]).view(dtype)[:, 0]

    if ros1:
        sec, nsec, base = column(4, '<u4'), column(8, '<u4'), 12
        strlen = column(12, '<u4')
        if np.any(strlen != strlen[0]):
            return None
        length = int(strlen[0])
        frame_id = bytes(buf[0, 16:16 + length]).decode('utf-8', 'replace')
        start = 16 + length
    else:
        if raws[0][1] != 1:   # CDR_LE only
            return None
        sec, nsec, base = column(4, '<i4'), column(8, '<u4'), 4
        strlen = column(base + 8, '<u4')
        if np.any(strlen != strlen[0]):
            return None
        length = int(strlen[0])
        frame_id = bytes(buf[0, base + 12:base + 12 + max(length - 1, 0)]).decode(
            'utf-8', 'replace')
        start = base + ((12 + length + 7) // 8) * 8
    if start + 37 * 8 > size:
        return None
    values = np.ascontiguousarray(buf[:, start:start + 37 * 8]).view('<f8').reshape(n, 37)
    return {'header_ns': sec.astype(np.int64) * 1_000_000_000 + nsec.astype(np.int64),
            'frame_id': frame_id, 'gyro': values[:, 13:16].astype(float),
            'gyro_provided': bool(np.any(values[:, 16] != -1.0)),
            'accel': values[:, 25:28].astype(float)}


def navsat_fix(msg: Any) -> Tuple[float, float, float, int]:
    """Return ``(latitude deg, longitude deg, altitude m, status)`` of a NavSatFix."""
    return (float(msg.latitude), float(msg.longitude), float(msg.altitude),
            int(msg.status.status))


def imu_orientation(msg: Any) -> Optional[np.ndarray]:
    """Return an Imu's orientation ``(4,)`` x y z w, or None when not provided (REP-145)."""
    if float(msg.orientation_covariance[0]) == -1.0:
        return None
    q = msg.orientation
    return np.array([q.x, q.y, q.z, q.w], dtype=float)
