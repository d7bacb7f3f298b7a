"""Write the simulators' data as bags (rosbag2 mcap, rosbag2 sqlite3, ROS 1): tests, benchmark."""
from pathlib import Path
from typing import Any, Optional, Sequence, Tuple

from accelcal_ros.recording.writer import BagWriter, sensor_data_qos
import numpy as np

FORMATS = ('mcap', 'sqlite3', 'ros1')
T0_NS = 1_700_000_000 * 10**9


def bag_path(tmp_path: Path, name: str, fmt: str) -> Path:
    """Return the output path of a bag in ``fmt`` (ROS 1: a .bag file)."""
    return tmp_path / (f'{name}.bag' if fmt == 'ros1' else f'{name}_{fmt}')


def write_imu_bag(path: Path, fmt: str, t: np.ndarray, accel: np.ndarray,
                  gyro: Optional[np.ndarray] = None, topic: str = '/imu/data_raw',
                  frame_id: str = 'imu_link', receive_offset_s: float = 0.0,
                  extra_topics: Sequence[Tuple[str, str]] = ()) -> Path:
    """IMU samples (s, m/s^2, rad/s) as sensor_msgs/Imu; ``extra_topics``: (topic, type)."""
    with BagWriter(path, fmt) as writer:
        writer.add_topic(topic, 'sensor_msgs/Imu', [sensor_data_qos()])
        for name, msgtype in extra_topics:
            writer.add_topic(name, msgtype)
        for k, (ti, ai) in enumerate(zip(t, accel)):
            ns = T0_NS + int(round(ti * 1e9))
            msg = writer.imu_message(ns, ai, frame_id, None if gyro is None else gyro[k],
                                     topic=topic)
            writer.write(topic, ns + int(round(receive_offset_s * 1e9)), msg)
    return path


def write_protocol_bag(path: Path, fmt: str, protocol: Sequence[Any],
                       imu_topic: str = '/imu/data', points_topic: str = '/velodyne_points',
                       scans_per_position: int = 2) -> Path:
    """
    Paper B's protocol as one continuous recording: the positions' IMU logs one after the other.

    Each position contributes its log (handling motion, then still) shifted in time; its
    scan is recorded ``scans_per_position`` times inside the still part (the middle one at
    the middle of the period).
    """
    with BagWriter(path, fmt) as writer:
        writer.add_topic(imu_topic, 'sensor_msgs/Imu', [sensor_data_qos()])
        writer.add_topic(points_topic, 'sensor_msgs/PointCloud2', [sensor_data_qos()])
        offset = 0.0
        for pos in protocol:
            t = pos.imu.t - pos.imu.t[0] + offset
            still_start = t[0] + 1.5
            mid = 0.5 * (still_start + t[-1])
            scan_times = mid + 0.1 * (np.arange(scans_per_position) - scans_per_position // 2)
            events = [(ti, 'imu', k) for k, ti in enumerate(t)]
            events += [(ts, 'scan', 0) for ts in scan_times]
            for ti, kind, k in sorted(events, key=lambda e: e[0]):
                ns = T0_NS + int(round(ti * 1e9))
                if kind == 'imu':
                    writer.write(imu_topic, ns, writer.imu_message(
                        ns, pos.imu.accel[k], 'imu_link',
                        None if pos.imu.gyro is None else pos.imu.gyro[k], topic=imu_topic))
                else:
                    writer.write(points_topic, ns, writer.pointcloud2_message(
                        ns, pos.cloud, 'lidar_link', topic=points_topic))
            offset = t[-1] + 1.0 / 200.0
    return path
