"""
Whole streams from a recording, as the offline commands use them, with stamp checks.

Time of a message (s): its header stamp by default (the sensor's clock, as the nodes use
it); ``stamp='receive'`` takes the bag's receive time instead, and a message whose header
stamp is zero always takes its receive time. :func:`check_stamps` warns (with counts) when
the times go backwards or jump, and when the header stamps are far from the receive times
(saying which one is used).

:func:`read_imu` loads an IMU topic into arrays (an IMU topic is small: 200 Hz for an hour
is 720 000 samples, 50 MB); clouds and images are streamed by the commands themselves.
"""
from dataclasses import dataclass, field
import math
from typing import Any, List, Optional, Tuple, TYPE_CHECKING

from accelcal_ros.errors import InputError
from accelcal_ros.recording import convert
from accelcal_ros.recording.bag import BagMessage, BagReader
import numpy as np

if TYPE_CHECKING:
    from accelcal_ros.sensor.model import SensorModel

HEADER_RECEIVE_WARN_S = 0.5
"""Median |header - receive| above which the choice of stamp is stated."""
JUMP_FACTOR = 10.0
"""A gap longer than this many median periods (and than 0.1 s) is a jump."""


def message_time_ns(message: BagMessage, stamp: str) -> int:
    """Return the time of a message in ns: header stamp, or receive time (see module doc)."""
    header = message.header_ns
    return message.receive_ns if stamp == 'receive' or header == 0 else header


def message_time_s(message: BagMessage, stamp: str) -> float:
    """Return :func:`message_time_ns` in s (absolute: about 0.2 us resolution in 2020s)."""
    return message_time_ns(message, stamp) * 1e-9


def used_times_ns(header_ns: np.ndarray, receive_ns: np.ndarray, stamp: str) -> np.ndarray:
    """Return the times used (int64 ns) of a topic's messages (see the module docstring)."""
    header_ns = np.asarray(header_ns, dtype=np.int64)
    receive_ns = np.asarray(receive_ns, dtype=np.int64)
    return receive_ns if stamp == 'receive' else np.where(header_ns != 0, header_ns, receive_ns)


def check_stamps(topic: str, header_s: np.ndarray, receive_s: np.ndarray, stamp: str,
                 repeats: bool = False) -> List[str]:
    """
    Return warnings about a topic's times (``header_s`` 0 where there is no header).

    Backwards steps and jumps are counted on the times used (and, with ``repeats``, times
    equal to the previous one: images, which no later step sorts out); the header/receive
    offset is reported when its median magnitude exceeds :data:`HEADER_RECEIVE_WARN_S`.
    """
    header_s = np.asarray(header_s, dtype=float)
    receive_s = np.asarray(receive_s, dtype=float)
    warnings = []
    has_header = header_s != 0
    used = receive_s if stamp == 'receive' else np.where(has_header, header_s, receive_s)
    if stamp == 'header' and has_header.any() and not has_header.all():
        warnings.append(f'{topic}: {int((~has_header).sum())} of {len(used)} messages have a '
                        'zero header stamp; their receive time is used')
    if has_header.any():
        offset = header_s[has_header] - receive_s[has_header]
        median = float(np.median(offset))
        if abs(median) > HEADER_RECEIVE_WARN_S:
            which = ('receive times (--stamp receive)' if stamp == 'receive' else
                     'header stamps (--stamp receive uses the receive times)')
            warnings.append(f'{topic}: header stamps differ from the bag receive times by '
                            f'{median:+.3f} s (median; max |{np.max(np.abs(offset)):.3f}| s); '
                            f'using {which}')
    if len(used) > 2:
        steps = np.diff(used)
        back = int((steps < 0).sum())
        if back:
            warnings.append(f'{topic}: time goes backwards {back} times (largest '
                            f'{-float(steps.min()):.6f} s); '
                            + ('images are used in recording order' if repeats else
                               'messages are taken in time order'))
        same = int((steps == 0).sum())
        if repeats and same:
            warnings.append(f'{topic}: {same} of {len(used)} messages repeat the previous time '
                            '(a camera driver that does not stamp each frame?): they are '
                            'used with that time')
        forward = steps[steps > 0]
        if forward.size:
            period = float(np.median(forward))
            limit = max(JUMP_FACTOR * period, 0.1)
            jumps = steps > limit
            if jumps.any():
                k = int(np.argmax(steps))
                warnings.append(f'{topic}: {int(jumps.sum())} time jumps longer than '
                                f'{limit:.3f} s (largest {float(steps[k]):.3f} s at '
                                f'{used[k] - used[0]:.3f} s into the topic)')
    return warnings


@dataclass
class ImuStream:
    """
    An IMU topic: specific force (N, 3) m/s^2, rate (N, 3) rad/s or None.

    ``t`` (s) counts from ``epoch_ns`` (the first sample's time, ns): relative times keep
    full float resolution, ``(ns - epoch_ns) / 1e9`` is exactly the decimal a CSV holds.
    """

    topic: str
    t: np.ndarray
    accel: np.ndarray
    gyro: Optional[np.ndarray]
    frame_id: str
    epoch_ns: int = 0
    warnings: List[str] = field(default_factory=list)


def _sorted_unique(topic: str, t: np.ndarray, *columns: Optional[np.ndarray]
                   ) -> Tuple[np.ndarray, List[Any], List[str]]:
    """Sort by time (stable) and drop repeated stamps; returns (t, arrays, warnings)."""
    warnings = []
    order = np.argsort(t, kind='stable')
    t = t[order]
    arrays: List[Any] = [None if a is None else a[order] for a in columns]
    keep = np.concatenate([[True], np.diff(t) > 0])
    if not keep.all():
        warnings.append(f'{topic}: {int((~keep).sum())} messages repeat a time already seen; '
                        'dropped')
        t = t[keep]
        arrays = [None if a is None else a[keep] for a in arrays]
    return t, arrays, warnings


IMU_CHUNK = 50_000
"""Serialised Imu messages decoded at once (bounds the raw bytes held: about 16 MB)."""


def read_imu(bag: BagReader, topic: Optional[str], option: str = '--topic') -> ImuStream:
    """
    Read a sensor_msgs/Imu topic (chosen as :meth:`BagReader.select_topic` does).

    Messages are decoded in chunks with :func:`~accelcal_ros.recording.convert.
    imu_arrays_from_raw` (vectorised), one by one where a chunk's layout varies.
    """
    name = bag.select_topic(topic, (convert.IMU,), option)
    header_parts: List[np.ndarray] = []
    receive_parts: List[np.ndarray] = []
    accel_parts: List[np.ndarray] = []
    gyro_parts: List[np.ndarray] = []
    provided = False
    frame_id = ''
    raws: List[bytes] = []
    stamps: List[int] = []

    def flush() -> None:
        nonlocal provided, frame_id
        fast = convert.imu_arrays_from_raw(raws, bag.is_ros1)
        if fast is None:
            for raw in raws:
                msg = bag.deserialize(raw, convert.IMU)
                a, w, p = convert.imu_values(msg)
                accel_parts.append(a[None, :])
                gyro_parts.append(w[None, :])
                provided = provided or p
                header_parts.append(np.array([int(msg.header.stamp.sec) * 1_000_000_000
                                              + int(msg.header.stamp.nanosec)],
                                             dtype=np.int64))
                frame_id = frame_id or str(msg.header.frame_id)
        else:
            accel_parts.append(fast['accel'])
            gyro_parts.append(fast['gyro'])
            header_parts.append(fast['header_ns'])
            provided = provided or fast['gyro_provided']
            frame_id = frame_id or fast['frame_id']
        receive_parts.append(np.array(stamps, dtype=np.int64))
        raws.clear()
        stamps.clear()

    for message in bag.messages([name], f'reading {name}', decode=()):
        raws.append(message.raw)
        stamps.append(message.receive_ns)
        if len(raws) >= IMU_CHUNK:
            flush()
    if raws:
        flush()
    header, receive = np.concatenate(header_parts), np.concatenate(receive_parts)
    used_ns = used_times_ns(header, receive, bag.stamp)
    epoch_ns = int(used_ns.min())
    warnings = _check_ns(name, header, receive, bag.stamp, epoch_ns)
    t = (used_ns - epoch_ns) / 1e9
    accel = np.concatenate(accel_parts).reshape(-1, 3)
    gyro_arr = np.concatenate(gyro_parts).reshape(-1, 3) if provided else None
    bad = ~np.all(np.isfinite(accel), axis=1)
    if bad.all():
        raise InputError(f'{name}: every linear_acceleration is NaN or infinite')
    t, (accel, gyro_arr), more = _sorted_unique(name, t, accel, gyro_arr)
    return ImuStream(name, t, accel, gyro_arr, frame_id, epoch_ns, warnings + more)


def _check_ns(name: str, header_ns: np.ndarray, receive_ns: np.ndarray, stamp: str,
              epoch_ns: int) -> List[str]:
    """:func:`check_stamps` on ns arrays, relative to ``epoch_ns`` (full resolution)."""
    header_ns = np.asarray(header_ns, dtype=np.int64)
    rel_header = np.where(header_ns != 0, (header_ns - epoch_ns) / 1e9, 0.0)
    rel_receive = (np.asarray(receive_ns, dtype=np.int64) - epoch_ns) / 1e9
    # a header stamp exactly at the epoch is not "no header": nudge it off zero
    rel_header[(header_ns != 0) & (rel_header == 0.0)] = 1e-12
    return check_stamps(name, rel_header, rel_receive, stamp)


class StampLog:
    """A topic's header and receive stamps, kept while its messages stream by."""

    def __init__(self) -> None:
        self.header_ns: List[int] = []
        self.receive_ns: List[int] = []

    def add(self, message: BagMessage) -> None:
        """Keep one message's stamps."""
        self.header_ns.append(message.header_ns)
        self.receive_ns.append(message.receive_ns)

    def warnings(self, topic: str, stamp: str, repeats: bool = False) -> List[str]:
        """Return :func:`check_stamps` of what was kept."""
        return check_stamps(topic, np.array(self.header_ns, dtype=np.int64) * 1e-9,
                            np.array(self.receive_ns, dtype=np.int64) * 1e-9, stamp, repeats)

    def times_s(self, stamp: str) -> np.ndarray:
        """Return the times used (absolute s; :func:`used_times_ns`)."""
        return used_times_ns(np.array(self.header_ns, dtype=np.int64),
                             np.array(self.receive_ns, dtype=np.int64), stamp) * 1e-9


@dataclass
class PoseStreamArrays:
    """Odometry poses: ``t`` (s), position (N, 3) m, quaternion (N, 4) x y z w."""

    topic: str
    t: np.ndarray
    position: np.ndarray
    quat: np.ndarray
    warnings: List[str] = field(default_factory=list)


def read_odometry(bag: BagReader, topic: Optional[str], option: str = '--odom'
                  ) -> PoseStreamArrays:
    """Read a nav_msgs/Odometry topic into arrays (sorted by time, repeats dropped)."""
    name = bag.select_topic(topic, (convert.ODOMETRY,), option)
    stamp_log = StampLog()
    pos: List[np.ndarray] = []
    quat: List[np.ndarray] = []
    for message in bag.messages([name], f'reading {name}'):
        p, q = convert.odometry_pose(message.msg)
        pos.append(p)
        quat.append(q)
        stamp_log.add(message)
    t, warnings = stamp_log.times_s(bag.stamp), stamp_log.warnings(name, bag.stamp)
    t, (position, quaternion), more = _sorted_unique(name, t, np.array(pos).reshape(-1, 3),
                                                     np.array(quat).reshape(-1, 4))
    return PoseStreamArrays(name, t, position, quaternion, warnings + more)


@dataclass
class AttitudeStream:
    """Attitude topic: ``t`` (s), roll and pitch (rad)."""

    topic: str
    t: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    warnings: List[str] = field(default_factory=list)


MAX_ATTITUDE_RAD = 2.0 * math.pi
"""Largest |roll|, |pitch| read from an attitude topic (rad); beyond it (1e300) a sample is
corrupt and skipped, as NaN and infinite ones are."""


def read_attitude(bag: BagReader, topic: Optional[str], option: str = '--attitude'
                  ) -> AttitudeStream:
    """
    Read the attitude node's geometry_msgs/Vector3Stamped topic (x roll, y pitch, rad).

    Samples with a NaN, infinite or absurd (beyond :data:`MAX_ATTITUDE_RAD`) roll or pitch
    are skipped with a warning (a frame is never levelled with them); none usable is an
    InputError.
    """
    name = bag.select_topic(topic, (convert.VECTOR3_STAMPED,), option)
    stamp_log = StampLog()
    rp: List[Tuple[float, float]] = []
    for message in bag.messages([name], f'reading {name}'):
        rp.append(convert.attitude_roll_pitch(message.msg))
        stamp_log.add(message)
    t, warnings = stamp_log.times_s(bag.stamp), stamp_log.warnings(name, bag.stamp)
    t, (roll_pitch,), more = _sorted_unique(name, t, np.array(rp).reshape(-1, 2))
    with np.errstate(invalid='ignore'):
        usable = np.all(np.abs(roll_pitch) <= MAX_ATTITUDE_RAD, axis=1)   # NaN: False
    if t.size and not usable.any():
        raise InputError(f'{name}: no usable roll/pitch: all {t.size} samples are NaN, '
                         f'infinite or beyond +-{MAX_ATTITUDE_RAD:.4g} rad')
    if not usable.all():
        more.append(f'{name}: {int(np.count_nonzero(~usable))} of {t.size} samples with a '
                    'NaN, infinite or absurd roll/pitch skipped')
        t, roll_pitch = t[usable], roll_pitch[usable]
    return AttitudeStream(name, t, roll_pitch[:, 0], roll_pitch[:, 1], warnings + more)


UNCALIBRATED_MAGNITUDE_G = 0.01
"""An IMU topic used without ``--calibration`` whose median magnitude is further than this
from 1 g (a raw ADXL345 reads 0.85-1.15 g at rest) is said to look uncalibrated."""


def attitude_series(bag: BagReader, attitude_topic: Optional[str], imu_topic: Optional[str],
                    model: Optional['SensorModel'] = None
                    ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, List[str]]:
    """
    Return ``(t_s absolute, roll, pitch, warnings)`` from an attitude or an IMU topic.

    ``attitude_topic`` and ``imu_topic`` both, or ``model`` (``--calibration``) with an
    ``attitude_topic``, are refused: one would be ignored. Neither: the bag's attitude
    topic, else its IMU topic. An IMU topic without ``model`` whose readings are not 1 g
    (:data:`UNCALIBRATED_MAGNITUDE_G`) is warned about: p2p over such a bag was 10 deg of
    yaw and 1.1 m off with status 0 and no word.
    """
    if attitude_topic is not None and imu_topic is not None:
        raise InputError('give --attitude TOPIC or --imu TOPIC, not both: the attitude comes '
                         'from one of them')
    if attitude_topic is not None and model is not None:
        raise InputError('--calibration corrects the accelerometer of --imu; --attitude '
                         'gives a finished roll/pitch it would not touch: leave one out')
    if attitude_topic is not None or imu_topic is None:
        try:
            att = read_attitude(bag, attitude_topic)
            return att.t, att.roll, att.pitch, att.warnings
        except InputError:
            if attitude_topic is not None:
                raise
    from accelcal_ros.sensor.tilt_series import estimate_series
    from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2

    imu = read_imu(bag, imu_topic, '--imu')
    # the adaptive filter (gyro-aided when the Imu carries angular velocity): a frame is
    # stitched with the estimate at its stamp, not with one raw sample
    estimates = estimate_series(imu.t, imu.accel / STANDARD_GRAVITY_M_S2, imu.gyro,
                                sensor_model=model)
    keep_t, roll, pitch = [], [], []
    for ti, est in zip(imu.t, estimates):
        if est is not None:
            keep_t.append(ti)
            roll.append(est.roll)
            pitch.append(est.pitch)
    if not keep_t:
        raise InputError(f'{imu.topic}: no sample gives a roll/pitch (all NaN or zero?)')
    t = imu.epoch_ns / 1e9 + np.array(keep_t)
    warnings = list(imu.warnings)
    if model is None:
        with np.errstate(over='ignore', invalid='ignore'):   # a corrupt 1e300 sample: inf
            magnitude = np.linalg.norm(imu.accel, axis=1) / STANDARD_GRAVITY_M_S2
        median = float(np.median(magnitude[np.isfinite(magnitude)])) if len(magnitude) else 1.0
        if abs(median - 1.0) > UNCALIBRATED_MAGNITUDE_G:
            warnings.append(f'{imu.topic}: the readings look uncalibrated (median |a| '
                            f'{median:.3f} g, not 1) and no --calibration is given: roll and '
                            'pitch may be off by degrees')
    return t, np.array(roll), np.array(pitch), warnings
