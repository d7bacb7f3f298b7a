"""
A rig capture from one continuous recording (core of ``accelcal rig-calibrate BAG``).

Still poses. The IMU topic (sensor_msgs/Imu, :func:`~accelcal_ros.recording.streams.
read_imu`) is read whole and its still segments found by the one stillness detector
(:func:`accelcal_ros.sensor.stillness.still_segments`: accelerometer, and the gyro when
the messages carry it, REP-145 ``angular_velocity_covariance[0] != -1``). Each segment at
least ``min_still_s`` long is one pose, named ``poseNN`` in time order.

Frame sets. The image topics (sensor_msgs/Image or CompressedImage; camera ``i`` is named
after its topic, :func:`camera_name`) are streamed in time order; each camera's newest
image is kept, and whenever every camera has one and their stamps lie within ``sync_s``,
that set is a candidate for the segment holding all its stamps. Each segment keeps the
candidate whose mean stamp is nearest its middle (away from the motion at its ends). A
segment without a complete set is dropped (reported). Times are the header stamps (or
the receive times, ``BagReader(stamp='receive')``), in s from the first IMU sample.

Output. The chosen images (as recorded: PNG, lossless) and each segment's accelerometer
samples (``imu.csv``: t,ax,ay,az in s and m/s^2, raw; :data:`TRIM_S` left out at both
ends, where the accelerometer alone may still see the rig settling) are written as the
capture directory ``DIR/poseNN/<camera>.png`` that
:func:`accelcal_ros.rig.calibrate.calibrate_directory` reads: a bag and a directory go
through one calibration. A segment's images are written
as soon as the stream has passed it, so memory holds one frame set per open segment.
"""
from dataclasses import dataclass
import os
from typing import Dict, List, Optional, Sequence, Tuple

from accelcal_ros.errors import InputError
from accelcal_ros.fileio import write_bytes_atomic
from accelcal_ros.recording import convert
from accelcal_ros.recording.bag import BagMessage, BagReader
from accelcal_ros.recording.streams import message_time_ns, read_imu, StampLog
from accelcal_ros.sensor.recording import save_recording
from accelcal_ros.sensor.stillness import SegmentStats, still_segments
import cv2
import numpy as np

IMAGE_TYPES = (convert.IMAGE, convert.COMPRESSED_IMAGE)
_TOPIC_SUFFIXES = ('compressed', 'image_raw', 'image', 'image_rect', 'image_color',
                   'image_mono', 'image_rect_color', 'image_rect_mono')
FINISH_AFTER_S = 1.0
"""A segment's frame set is written once the stream is this far past its end (s)."""
TRIM_S = 0.1
"""Samples this close to a still segment's ends are left out of its imu.csv (s)."""


def camera_name(topic: str) -> str:
    """
    Return the camera name of an image topic: ``/cam0/image_raw`` -> ``cam0``.

    The last namespace left after dropping image suffixes (``image_raw``, ``compressed``,
    ``image_rect``, ...); a topic of suffixes only keeps its full name with ``_``.
    """
    parts = [p for p in topic.strip('/').split('/') if p]
    while len(parts) > 1 and parts[-1] in _TOPIC_SUFFIXES:
        parts.pop()
    return parts[-1] if parts else 'camera'


def camera_names(topics: Sequence[str]) -> List[str]:
    """Return one distinct camera name per topic (the full topic with ``_`` on a clash)."""
    names = [camera_name(t) for t in topics]
    if len(set(names)) != len(names):
        names = [t.strip('/').replace('/', '_') for t in topics]
    return names


@dataclass
class BagCapture:
    """What :func:`extract_capture` wrote and noticed."""

    directory: str
    cameras: List[str]
    topics: List[str]
    poses: List[str]
    spans: List[str]
    dropped: Dict[str, str]
    warnings: List[str]


@dataclass
class _Candidate:
    distance_s: float
    stamps_s: List[float]
    messages: List[BagMessage]


def _write_pose(folder: str, names: Sequence[str], candidate: _Candidate,
                sizes: Dict[str, Tuple[int, int]], topics: Sequence[str]) -> None:
    os.makedirs(folder, exist_ok=True)
    for name, topic, stamp, message in zip(names, topics, candidate.stamps_s,
                                           candidate.messages):
        image = convert.image_array(message.msg, message.msgtype)
        size = (int(image.shape[1]), int(image.shape[0]))
        first = sizes.setdefault(name, size)
        if first != size:
            raise InputError(f'{topic}: images of different sizes ({first[0]}x{first[1]}, then '
                             f'{size[0]}x{size[1]} at {stamp:.3f} s); one camera must keep '
                             'one resolution')
        ok, png = cv2.imencode('.png', image)
        if not ok:
            raise InputError(f'{topic}: the image at {stamp:.3f} s cannot be encoded as PNG')
        write_bytes_atomic(os.path.join(folder, f'{name}.png'), png.tobytes())


def capture_topics(bag: BagReader, image_topics: Optional[Sequence[str]]
                   ) -> Tuple[List[str], List[str]]:
    """
    Return the image topics of the capture and their camera names (reads no message).

    ``image_topics`` None: every Image/CompressedImage topic of the bag, in sorted order;
    InputError when a topic is missing, of the wrong type or named twice.
    """
    if image_topics:
        topics = [bag.select_topic(t, IMAGE_TYPES, f'--images (camera {i})')
                  for i, t in enumerate(image_topics)]
        if len(set(topics)) != len(topics):
            raise InputError(f'--images names a topic twice: {" ".join(topics)}')
    else:
        topics = sorted(t.name for t in bag.topics().values() if t.msgtype in IMAGE_TYPES)
        if not topics:
            raise InputError(f'{bag.path} has no sensor_msgs/Image or CompressedImage topic; '
                             f'it has: {bag.listing()}')
    return topics, camera_names(topics)


def extract_capture(bag: BagReader, image_topics: Optional[Sequence[str]],
                    imu_topic: Optional[str], directory: str, sync_s: float = 0.05,
                    min_still_s: float = 1.0) -> BagCapture:
    """
    Write the capture directory of a recording into ``directory`` (see the module docstring).

    ``image_topics`` None: every Image/CompressedImage topic of the bag, in sorted order.
    Raises InputError when a topic is missing or of the wrong type, the IMU never holds
    still for ``min_still_s``, no still segment has a complete frame set, or a camera's
    images change size.
    """
    topics, names = capture_topics(bag, image_topics)
    imu = read_imu(bag, imu_topic, '--imu')
    warnings = list(imu.warnings)
    if imu.gyro is None:
        warnings.append(f'{imu.topic} carries no angular rate: still poses are found from '
                        'the accelerometer')
    segments: List[SegmentStats] = still_segments(imu.t, imu.accel, imu.gyro,
                                                  accel_unit_m_s2=1.0, min_still_s=min_still_s)
    if not segments:
        spread = float(np.max(np.std(imu.accel, axis=0))) if len(imu.t) > 1 else 0.0
        raise InputError(f'{imu.topic}: the IMU never holds still for {min_still_s:g} s '
                         f'({len(imu.t)} samples over {imu.t[-1] - imu.t[0]:.1f} s, '
                         f'accelerometer spread {spread:.2f} m/s^2): no still pose found; hold '
                         'the rig still for each pose')
    starts = np.array([s.t_start_s for s in segments])
    stops = np.array([s.t_end_s for s in segments])
    middles = 0.5 * (starts + stops)
    pose_names = [f'pose{k:02d}' for k in range(len(segments))]
    best: Dict[int, _Candidate] = {}
    done: List[bool] = [False] * len(segments)
    sizes: Dict[str, Tuple[int, int]] = {}
    index = {topic: i for i, topic in enumerate(topics)}
    latest: List[Optional[Tuple[float, BagMessage]]] = [None] * len(topics)
    stamp_logs = [StampLog() for _ in topics]
    os.makedirs(directory, exist_ok=True)

    def finish(k: int) -> None:
        done[k] = True
        candidate = best.pop(k, None)
        if candidate is not None:
            _write_pose(os.path.join(directory, pose_names[k]), names, candidate, sizes,
                        topics)

    for message in bag.messages(topics, 'reading images'):
        i = index[message.topic]
        t = (message_time_ns(message, bag.stamp) - imu.epoch_ns) / 1e9
        stamp_logs[i].add(message)
        latest[i] = (t, message)
        for passed in np.nonzero(~np.array(done) & (stops < t - FINISH_AFTER_S))[0].tolist():
            finish(passed)
        if any(item is None for item in latest):
            continue
        stamps = [item[0] for item in latest if item is not None]
        if max(stamps) - min(stamps) > sync_s:
            continue
        k = int(np.searchsorted(starts, min(stamps), side='right')) - 1
        if k < 0 or done[k] or max(stamps) > stops[k]:
            continue
        distance = abs(float(np.mean(stamps)) - middles[k])
        if k not in best or distance < best[k].distance_s:
            best[k] = _Candidate(distance, stamps,
                                 [item[1] for item in latest if item is not None])
    for k in range(len(segments)):
        if not done[k]:
            finish(k)
    for i, topic in enumerate(topics):
        warnings += stamp_logs[i].warnings(topic, bag.stamp)
    poses, spans, dropped = [], [], {}
    for k, seg in enumerate(segments):
        name = pose_names[k]
        span = f'{seg.t_start_s:.2f}..{seg.t_end_s:.2f} s'
        folder = os.path.join(directory, name)
        if not os.path.isdir(folder):
            dropped[name] = (f'still {span} into {imu.topic} but no set of {len(topics)} '
                             f'images within {sync_s:g} s in it')
            continue
        i0 = int(np.searchsorted(imu.t, seg.t_start_s + TRIM_S))
        i1 = int(np.searchsorted(imu.t, seg.t_end_s - TRIM_S, side='right'))
        if i1 - i0 < 3:
            i0, i1 = seg.start, seg.stop
        save_recording(os.path.join(folder, 'imu.csv'), imu.t[i0:i1], imu.accel[i0:i1])
        poses.append(name)
        spans.append(f'{name}: still {span} into {imu.topic}')
    if not poses:
        raise InputError(f'{len(segments)} still poses found in {imu.topic} but none holds a '
                         f'set of images of {", ".join(topics)} within --sync-s {sync_s:g} s: '
                         'check --images and the camera stamps')
    return BagCapture(directory, names, topics, poses, spans, dropped, warnings)
