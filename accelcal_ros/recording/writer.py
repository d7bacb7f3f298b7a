"""
Write bags without ROS: rosbag2 (mcap or sqlite3 directory) and ROS 1 (``.bag`` file).

:class:`BagWriter` writes into a hidden sibling path and renames it into place on
:meth:`BagWriter.close` (atomic like :mod:`accelcal_ros.fileio`: a failed command leaves no
half-written bag); an existing target is refused, as ``ros2 bag record`` does.
:func:`imu_message` builds the sensor_msgs/Imu the driver publishes (REP-145: orientation
and rate covariance element 0 = -1, "not provided"); :func:`sensor_data_qos` is rclpy's
``qos_profile_sensor_data`` (best effort, volatile, keep last 5) as offered-QoS metadata,
so ``ros2 bag play`` replays with the driver's QoS.
"""
from enum import IntEnum
import os
from pathlib import Path
import shutil
from typing import Any, Dict, List, Optional, Sequence, Union

from accelcal_ros.errors import FileFormatError, InputError
from accelcal_ros.recording.bag import damage_errors
import numpy as np

FORMATS = ('mcap', 'sqlite3', 'ros1')

PathLike = Union[str, 'os.PathLike[str]']
Vector = Union[Sequence[float], np.ndarray]


class PointFieldType(IntEnum):
    """The ``datatype`` constants of sensor_msgs/PointField."""

    INT8 = 1
    UINT8 = 2
    INT16 = 3
    UINT16 = 4
    INT32 = 5
    UINT32 = 6
    FLOAT32 = 7
    FLOAT64 = 8


POINTFIELD_TYPE_OF_DTYPE = {
    'i1': PointFieldType.INT8, 'u1': PointFieldType.UINT8, 'i2': PointFieldType.INT16,
    'u2': PointFieldType.UINT16, 'i4': PointFieldType.INT32, 'u4': PointFieldType.UINT32,
    'f4': PointFieldType.FLOAT32, 'f8': PointFieldType.FLOAT64}
"""PointField datatype of a numpy dtype's kind and size (``dtype.str[1:]``)."""


def full_type(msgtype: str) -> str:
    """Return rosbags' ``pkg/msg/Type`` for ``pkg/Type`` or ``pkg/msg/Type``."""
    parts = msgtype.split('/')
    return msgtype if len(parts) == 3 else f'{parts[0]}/msg/{parts[-1]}'


def format_for(path: PathLike, fmt: Optional[str] = None) -> str:
    """Return the bag format for an output path: ``ros1`` for ``*.bag``, else ``fmt`` or mcap."""
    if str(path).lower().endswith('.bag'):
        if fmt not in (None, 'ros1'):
            raise InputError(f'{path}: a .bag file is a ROS 1 bag, not {fmt}')
        return 'ros1'
    if fmt == 'ros1':
        raise InputError(f'{path}: a ROS 1 bag must end in .bag')
    if str(path).rstrip('/').lower().endswith(('.db3', '.mcap')):   # was a folder y.db3/y.db3.mcap
        raise InputError(f'{path}: a rosbag2 bag is a directory (its storage file is made '
                         'inside it): name it without .db3 or .mcap; --format picks the '
                         'storage (mcap or sqlite3)')
    return fmt or 'mcap'


def sensor_data_qos() -> Any:
    """Return rclpy's ``qos_profile_sensor_data`` as a rosbags Qos (offered-QoS metadata)."""
    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                    QosReliability, QosTime)

    zero = QosTime(0, 0)
    return Qos(QosHistory.KEEP_LAST, 5, QosReliability.BEST_EFFORT, QosDurability.VOLATILE,
               zero, zero, QosLiveliness.SYSTEM_DEFAULT, zero, False)


class BagWriter:
    """Write messages to a new bag; use as a context manager (renames into place on success)."""

    def __init__(self, path: PathLike, fmt: Optional[str] = None) -> None:
        from rosbags.typesys import get_typestore, Stores

        self.path = Path(path)
        self.format = format_for(self.path, fmt)
        if fmt is not None and fmt not in FORMATS:
            raise InputError(f'bag format must be one of {", ".join(FORMATS)}, not {fmt!r}')
        if self.path.exists():
            raise InputError(f'{self.path} exists; remove it or choose another output')
        parent = self.path.parent if str(self.path.parent) else Path('.')
        if not parent.is_dir():
            raise InputError(f'{self.path}: directory {parent} does not exist')
        self._tmp = parent / f'.{self.path.name}.partial-{os.getpid()}'
        self._remove_tmp()
        self.typestore = get_typestore(Stores.ROS1_NOETIC if self.format == 'ros1'
                                       else Stores.ROS2_JAZZY)
        self._writer: Any  # rosbags.rosbag1.Writer or rosbags.rosbag2.Writer
        if self.format == 'ros1':
            from rosbags.rosbag1 import Writer as Ros1Writer

            self._writer = Ros1Writer(self._tmp)
        else:
            from rosbags.rosbag2 import StoragePlugin, Writer as Ros2Writer

            plugin = StoragePlugin.MCAP if self.format == 'mcap' else StoragePlugin.SQLITE3
            self._writer = Ros2Writer(self._tmp, version=9, storage_plugin=plugin)
        self._writer.open()
        self._conns: Dict[str, Any] = {}
        self._seq: Dict[str, int] = {}
        self.count = 0

    def _remove_tmp(self) -> None:
        if self._tmp.is_dir():
            shutil.rmtree(self._tmp)
        elif self._tmp.exists():
            self._tmp.unlink()

    def add_topic(self, topic: str, msgtype: str, qos: Sequence[Any] = (),
                  source: Any = None) -> None:
        """
        Declare ``topic`` of ``msgtype`` (``pkg/Type``) with offered QoS profiles.

        Types outside the standard set need ``source``, the rosbags Connection the
        messages come from (its definition and digest are copied).
        """
        if topic in self._conns:
            return
        mtype = full_type(msgtype)
        known = mtype in self.typestore.types
        kwargs: Dict[str, Any] = {}
        if not known:
            if source is None:
                raise InputError(f'message type {msgtype} is unknown; cannot write {topic}')
            kwargs = {'msgdef': source.msgdef.data}
            if self.format == 'ros1':
                kwargs['md5sum'] = source.digest
            else:
                kwargs['rihs01'] = source.digest
        else:
            kwargs = {'typestore': self.typestore}
        if self.format == 'ros1':
            self._conns[topic] = self._writer.add_connection(topic, mtype, **kwargs)
        else:
            self._conns[topic] = self._writer.add_connection(
                topic, mtype, offered_qos_profiles=list(qos), **kwargs)

    def write(self, topic: str, receive_ns: int, msg: Any) -> None:
        """Serialise ``msg`` (a rosbags message object) onto a declared topic."""
        conn = self._conns[topic]
        if self.format == 'ros1':
            data = self.typestore.serialize_ros1(msg, conn.msgtype)
        else:
            data = self.typestore.serialize_cdr(msg, conn.msgtype)
        self.write_raw(topic, receive_ns, data)

    def write_raw(self, topic: str, receive_ns: int,
                  data: Union[bytes, memoryview, np.ndarray]) -> None:
        """Write already serialised bytes (this bag's serialisation) onto a declared topic."""
        self._writer.write(self._conns[topic], int(receive_ns), data)
        self.count += 1

    def close(self) -> None:
        """Finish the bag and move it into place."""
        try:
            self._writer.close()
        except damage_errors() as exc:
            self._remove_tmp()
            raise FileFormatError(self.path, f'cannot finish the bag: {exc}') from None
        if self.format != 'ros1':
            # rosbag2 names its storage file after the directory: keep that convention
            for child in list(self._tmp.iterdir()):
                if child.name.startswith(self._tmp.name):
                    child.rename(self._tmp / (self.path.name + child.name[len(self._tmp.name):]))
            meta = self._tmp / 'metadata.yaml'
            meta.write_text(meta.read_text().replace(self._tmp.name, self.path.name))
        os.replace(self._tmp, self.path)

    def abort(self) -> None:
        """Drop the partial bag."""
        try:
            self._writer.close()
        except damage_errors():
            pass  # the partial bag is dropped anyway
        self._remove_tmp()

    def __enter__(self) -> 'BagWriter':
        """Return the writer."""
        return self

    def __exit__(self, exc_type: Optional[type], *rest: object) -> None:
        """Close on success, drop the partial bag on error."""
        if exc_type is None:
            self.close()
        else:
            self.abort()

    # -- messages ------------------------------------------------------------------------
    def header(self, t_ns: int, frame_id: str, topic: str = '') -> Any:
        """Return a std_msgs/Header for this bag's type set (ROS 1 headers count ``seq``)."""
        types = self.typestore.types
        stamp = types['builtin_interfaces/msg/Time'](sec=int(t_ns // 1_000_000_000),
                                                     nanosec=int(t_ns % 1_000_000_000))
        header_type = types['std_msgs/msg/Header']
        if self.format == 'ros1':
            seq = self._seq.get(topic, 0)
            self._seq[topic] = seq + 1
            return header_type(seq=seq, stamp=stamp, frame_id=frame_id)
        return header_type(stamp=stamp, frame_id=frame_id)

    def imu_message(self, t_ns: int, accel_m_s2: Vector, frame_id: str,
                    gyro_rad_s: Optional[Vector] = None,
                    accel_covariance: Optional[Vector] = None, topic: str = '') -> Any:
        """Return a sensor_msgs/Imu as the driver publishes it (see the module docstring)."""
        types = self.typestore.types
        vec = types['geometry_msgs/msg/Vector3']
        quat = types['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0)
        a = [float(v) for v in accel_m_s2]
        orientation_cov = np.zeros(9)
        orientation_cov[0] = -1.0
        gyro_cov = np.zeros(9)
        if gyro_rad_s is None:
            gyro_cov[0] = -1.0
            w = [0.0, 0.0, 0.0]
        else:
            w = [float(v) for v in gyro_rad_s]
        accel_cov = (np.zeros(9) if accel_covariance is None
                     else np.asarray(accel_covariance, dtype=float).reshape(9))
        return types['sensor_msgs/msg/Imu'](
            header=self.header(t_ns, frame_id, topic), orientation=quat,
            orientation_covariance=orientation_cov,
            angular_velocity=vec(x=w[0], y=w[1], z=w[2]), angular_velocity_covariance=gyro_cov,
            linear_acceleration=vec(x=a[0], y=a[1], z=a[2]),
            linear_acceleration_covariance=accel_cov)

    def pointcloud2_message(self, t_ns: int, cloud: np.ndarray, frame_id: str,
                            topic: str = '') -> Any:
        """Return an unorganised sensor_msgs/PointCloud2 holding structured array ``cloud``."""
        cloud = np.ascontiguousarray(cloud)
        names = cloud.dtype.names
        if not names:
            raise InputError('a cloud to write must be a structured array (named fields)')
        packed = np.dtype([(n, cloud.dtype[n].newbyteorder('<')) for n in names])
        layout: Dict[str, Any] = dict(packed.fields or {})
        data = np.zeros(len(cloud), dtype=packed)
        types = self.typestore.types
        field_type = types['sensor_msgs/msg/PointField']
        fields: List[Any] = []
        for name in names:
            data[name] = cloud[name]
            code = POINTFIELD_TYPE_OF_DTYPE.get(packed[name].str[1:])
            if code is None:
                raise InputError(f'cloud field {name!r} ({packed[name]}) has no PointField type')
            fields.append(field_type(name=name, offset=layout[name][1], datatype=int(code),
                                     count=1))
        return types['sensor_msgs/msg/PointCloud2'](
            header=self.header(t_ns, frame_id, topic), height=1, width=len(cloud),
            fields=fields, is_bigendian=False, point_step=packed.itemsize,
            row_step=packed.itemsize * len(cloud),
            data=np.frombuffer(data.tobytes(), dtype=np.uint8), is_dense=True)

    def odometry_message(self, t_ns: int, position_m: Vector, quat_xyzw: Vector, frame_id: str,
                         child_frame_id: str, topic: str = '') -> Any:
        """Return a nav_msgs/Odometry: pose of ``child_frame_id`` in ``frame_id`` (no twist)."""
        types = self.typestore.types
        p = [float(v) for v in position_m]
        q = [float(v) for v in quat_xyzw]
        pose = types['geometry_msgs/msg/Pose'](
            position=types['geometry_msgs/msg/Point'](x=p[0], y=p[1], z=p[2]),
            orientation=types['geometry_msgs/msg/Quaternion'](x=q[0], y=q[1], z=q[2], w=q[3]))
        vec = types['geometry_msgs/msg/Vector3']
        twist = types['geometry_msgs/msg/Twist'](linear=vec(x=0.0, y=0.0, z=0.0),
                                                 angular=vec(x=0.0, y=0.0, z=0.0))
        with_cov = types['geometry_msgs/msg/PoseWithCovariance'](
            pose=pose, covariance=np.zeros(36))
        twist_cov = types['geometry_msgs/msg/TwistWithCovariance'](
            twist=twist, covariance=np.zeros(36))
        return types['nav_msgs/msg/Odometry'](
            header=self.header(t_ns, frame_id, topic), child_frame_id=child_frame_id,
            pose=with_cov, twist=twist_cov)

    def image_message(self, t_ns: int, image: np.ndarray, frame_id: str,
                      topic: str = '') -> Any:
        """Return a sensor_msgs/Image: ``mono8`` for (H, W) uint8, ``bgr8`` for (H, W, 3)."""
        image = np.ascontiguousarray(image, dtype=np.uint8)
        encoding = 'mono8' if image.ndim == 2 else 'bgr8'
        height, width = image.shape[:2]
        return self.typestore.types['sensor_msgs/msg/Image'](
            header=self.header(t_ns, frame_id, topic), height=height, width=width,
            encoding=encoding, is_bigendian=0, step=image.strides[0],
            data=image.reshape(-1).view(np.uint8))

    def camera_info_message(self, t_ns: int, k: Vector, d: Vector, width: int, height: int,
                            frame_id: str, distortion_model: str = 'plumb_bob',
                            topic: str = '') -> Any:
        """Return a sensor_msgs/CameraInfo (K 3x3, D, P = [K | 0], R = I)."""
        types = self.typestore.types
        k_matrix = np.asarray(k, dtype=float).reshape(3, 3)
        p = np.hstack([k_matrix, np.zeros((3, 1))]).reshape(-1)
        roi = types['sensor_msgs/msg/RegionOfInterest'](x_offset=0, y_offset=0, height=0,
                                                        width=0, do_rectify=False)
        fields: Dict[str, Any] = {
            'header': self.header(t_ns, frame_id, topic), 'height': int(height),
            'width': int(width), 'distortion_model': distortion_model, 'binning_x': 0,
            'binning_y': 0, 'roi': roi}
        arrays = {'d': np.asarray(d, dtype=float).reshape(-1), 'k': k_matrix.reshape(-1),
                  'r': np.eye(3).reshape(-1), 'p': p}
        for name, value in arrays.items():
            fields[name.upper() if self.format == 'ros1' else name] = value
        return types['sensor_msgs/msg/CameraInfo'](**fields)

    def vector3_stamped_message(self, t_ns: int, xyz: Vector, frame_id: str,
                                topic: str = '') -> Any:
        """Return a geometry_msgs/Vector3Stamped (the attitude node: x roll, y pitch, rad)."""
        types = self.typestore.types
        x, y, z = (float(v) for v in xyz)
        return types['geometry_msgs/msg/Vector3Stamped'](
            header=self.header(t_ns, frame_id, topic),
            vector=types['geometry_msgs/msg/Vector3'](x=x, y=y, z=z))
