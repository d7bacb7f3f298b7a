"""
LiDAR work on one continuous recording: boresight positions and georeferencing from a bag.

Boresight (:func:`collect_positions`). The IMU topic (sensor_msgs/Imu) is read whole and
its still periods found as for a directory
(:func:`accelcal_ros.lidar.static_segments.find_static_segments`: the gyro when the
messages carry it, REP-145 ``angular_velocity_covariance[0] != -1``, else the
accelerometer); each period's gravity is its mean specific force (m/s^2, IMU frame, the
calibration applied when given). The PointCloud2 topic is then streamed: a scan whose
time lies inside a still period joins it, and each period keeps the
``clouds_per_position`` scans nearest its middle (points concatenated, LiDAR frame, m).
A period without a scan is reported as dropped. Positions are named ``posNN`` in time
order, so the report and files are those of a directory.

Georeferencing (:func:`georeference_scans`): every scan of the topic, each point at
``p_nav = C(t) (R p_lidar + lever) + r(t)`` with its own time (the scan's stamp plus the
per-point time field), poses from a nav_msgs/Odometry topic or a CSV.
"""
import heapq
from typing import Dict, List, Optional, Tuple

from accelcal_ros.errors import InputError
from accelcal_ros.lidar.boresight import StaticPosition
from accelcal_ros.lidar.cloud import finite_mask, make_cloud, point_times, xyz
from accelcal_ros.lidar.poses import PoseStream
from accelcal_ros.lidar.static_segments import find_static_segments
from accelcal_ros.recording import convert
from accelcal_ros.recording.bag import BagReader
from accelcal_ros.recording.streams import (message_time_ns, message_time_s, read_imu,
                                            StampLog)
from accelcal_ros.sensor.model import SensorModel
import numpy as np
from numpy.typing import ArrayLike


def collect_positions(bag: BagReader, points_topic: Optional[str], imu_topic: Optional[str],
                      model: Optional[SensorModel] = None, clouds_per_position: int = 1,
                      static_options: Optional[dict] = None
                      ) -> Tuple[List[StaticPosition], Dict[str, str], List[str], List[str]]:
    """
    Return ``(positions, dropped, spans, warnings)`` of a recording (see module docstring).

    ``spans`` holds one line per still period (name, time span, scans used) for the report.
    """
    if clouds_per_position < 1:
        raise InputError('--clouds-per-position must be at least 1')
    points_name = bag.select_topic(points_topic, (convert.POINTCLOUD2,), '--points')
    imu = read_imu(bag, imu_topic, '--imu')
    warnings = list(imu.warnings)
    if imu.gyro is None:
        warnings.append(f'{imu.topic} carries no angular rate: still periods are found from '
                        'the accelerometer')
    segments = find_static_segments(imu.t, imu.accel, imu.gyro, model,
                                    **(static_options or {}))
    if not segments:
        raise InputError(f'{imu.topic}: the IMU never holds still long enough; no position '
                         'found in the recording')
    starts = np.array([s.t_start for s in segments])
    stops = np.array([s.t_stop for s in segments])
    middles = 0.5 * (starts + stops)
    kept: List[list] = [[] for _ in segments]   # heaps of (-|t - middle|, order, points)
    stamp_log = StampLog()
    outside = 0
    for k, message in enumerate(bag.messages([points_name], f'reading {points_name}')):
        t = (message_time_ns(message, bag.stamp) - imu.epoch_ns) / 1e9
        stamp_log.add(message)
        i = int(np.searchsorted(starts, t, side='right')) - 1
        if i < 0 or t > stops[i]:
            outside += 1
            continue
        heap = kept[i]
        item = (-abs(t - middles[i]), k, message)
        if len(heap) < clouds_per_position:
            heapq.heappush(heap, item)
        elif item[0] > heap[0][0]:
            heapq.heapreplace(heap, item)
    warnings += stamp_log.warnings(points_name, bag.stamp)
    positions, dropped, spans = [], {}, []
    for i, (seg, heap) in enumerate(zip(segments, kept)):
        name = f'pos{i + 1:02d}'
        span = f'{seg.t_start:.2f}..{seg.t_stop:.2f} s'
        if not heap:
            dropped[name] = f'still {span} into {imu.topic} but no scan of {points_name} in it'
            continue
        scans = [convert.cloud_array(item[2].msg) for item in sorted(heap, key=lambda x: x[1])]
        pts = np.concatenate([xyz(c) if len(c) else np.zeros((0, 3)) for c in scans])
        positions.append(StaticPosition(name, pts, seg.gravity_m_s2, seg.direction_std_rad(),
                                        calibrated=model is not None))
        spans.append(f'{name}: still {span} into {imu.topic}, {len(scans)} scan(s), '
                     f'{len(pts)} points')
    if outside:
        warnings.append(f'{points_name}: {outside} scans taken while moving (not used)')
    return positions, dropped, spans, warnings


def georeference_scans(bag: BagReader, points_topic: Optional[str], poses: PoseStream,
                       boresight: ArrayLike, lever_arm_m: ArrayLike = (0.0, 0.0, 0.0),
                       time_field: Optional[str] = None, max_gap_s: Optional[float] = None
                       ) -> Tuple[np.ndarray, Dict[str, int], List[str]]:
    """
    Georeference every scan of a PointCloud2 topic; returns ``(cloud, totals, warnings)``.

    ``cloud`` holds x y z (nav frame, float64), intensity and ring when present and the
    absolute ``timestamp`` (s); ``totals`` sums the per-scan GeorefStats fields.
    """
    from accelcal_ros.lidar.georef import georeference

    name = bag.select_topic(points_topic, (convert.POINTCLOUD2,), '--points')
    parts, stamp_log = [], StampLog()
    totals = {'total': 0, 'kept': 0, 'before_span': 0, 'after_span': 0, 'non_finite': 0,
              'in_gap': 0}
    for message in bag.messages([name], f'georeferencing {name}'):
        stamp_log.add(message)
        cloud = convert.cloud_array(message.msg)
        if not len(cloud):
            continue
        try:
            times = point_times(cloud, message_time_s(message, bag.stamp), time_field)
        except InputError as exc:
            raise InputError(f'{name}: {exc}') from None
        pts = xyz(cloud)
        good = finite_mask(pts)
        out, keep, stats = georeference(pts[good], times[good], poses, boresight, lever_arm_m,
                                        max_gap_s=max_gap_s)
        for key in totals:
            totals[key] += getattr(stats, key)
        totals['non_finite'] += int((~good).sum())
        totals['total'] += int((~good).sum())
        if stats.kept:
            sub = cloud[good][keep]
            names = cloud.dtype.names or ()
            parts.append(make_cloud(out, sub['intensity'] if 'intensity' in names else None,
                                    sub['ring'] if 'ring' in names else None,
                                    times[good][keep], 'timestamp', double=True))
    warnings = stamp_log.warnings(name, bag.stamp)
    if not parts:
        t0, t1 = poses.span
        raise InputError(f'no point of {name} lies in the span of the pose stream '
                         f'[{t0:.3f}, {t1:.3f}] s: wrong topic, or --stamp?')
    return np.concatenate(parts), totals, warnings
