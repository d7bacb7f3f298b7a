"""
P2P positioning over a recording: images + CameraInfo + attitude (or IMU) from one bag.

The ``p2p`` node's core (:class:`~accelcal_ros.p2p.pipeline.P2PPipeline`) is fed in
time order: the first valid sensor_msgs/CameraInfo, then each image (sensor_msgs/Image or
CompressedImage, streamed, converted to grey) after every attitude up to its stamp plus
the tolerance. The attitude is the attitude node's Vector3Stamped topic (x roll, y pitch,
rad) or, from a sensor_msgs/Imu topic, the roll/pitch of the calibrated specific force
(:class:`~accelcal_ros.sensor.tilt.TiltEstimator`, paper A eq. 7, the calibration
applied when given). Times are absolute seconds (header stamps unless ``--stamp receive``).
"""
from typing import Any, Dict, Iterable, Iterator, List, Optional, Tuple, TYPE_CHECKING

from accelcal_ros.errors import InputError
from accelcal_ros.recording import convert
from accelcal_ros.recording.bag import BagReader
from accelcal_ros.recording.streams import message_time_s, StampLog
import numpy as np

if TYPE_CHECKING:
    from accelcal_ros.p2p.pipeline import FrameResult, P2PPipeline


def first_camera_info(bag: BagReader, topic: Optional[str]) -> Dict[str, Any]:
    """Return :func:`~accelcal_ros.recording.convert.camera_info` of the first valid message."""
    name = bag.select_topic(topic, (convert.CAMERA_INFO,), '--camera-info')
    reason = ''
    for message in bag.messages([name], f'reading {name}'):
        try:
            return convert.camera_info(message.msg)
        except InputError as exc:
            reason = str(exc)
    raise InputError(f'{name}: no usable CameraInfo ({reason})')


def run_p2p(bag: BagReader, pipeline: 'P2PPipeline', image_topic: Optional[str],
            attitude: Tuple[np.ndarray, np.ndarray, np.ndarray],
            warnings: Optional[List[str]] = None) -> Iterator['FrameResult']:
    """
    Yield the :class:`~accelcal_ros.p2p.pipeline.FrameResult` of every image of a topic.

    ``attitude`` is ``(t_s, roll, pitch)`` arrays sorted by time; ``pipeline`` holds the
    camera already. ``warnings``, if given, gets the image topic's stamp checks at the
    end (20 images stamped alike were solved at one attitude without a word).
    """
    import cv2

    name = bag.select_topic(image_topic, (convert.IMAGE, convert.COMPRESSED_IMAGE), '--image')
    t_att, roll, pitch = attitude
    tolerance = pipeline.values['attitude_tolerance_s']
    fed = 0
    log = StampLog()
    for message in bag.messages([name], f'p2p on {name}'):
        log.add(message)
        stamp = message_time_s(message, bag.stamp)
        while fed < len(t_att) and t_att[fed] <= stamp + tolerance:
            yield from pipeline.add_attitude(float(t_att[fed]), roll[fed], pitch[fed])
            fed += 1
        image = convert.image_array(message.msg, message.msgtype)
        grey: np.ndarray = (image if image.ndim == 2
                            else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY))
        if grey.dtype != np.uint8:
            grey = (grey >> 8).astype(np.uint8)
        frame_id = str(message.msg.header.frame_id)
        yield from pipeline.add_image(stamp, frame_id, grey)
    if pipeline.pending is not None:
        pending, pipeline.pending = pipeline.pending, None
        yield pipeline._process(*pending)
    if warnings is not None:
        warnings += log.warnings(name, bag.stamp, repeats=True)


def results_csv(results: Iterable['FrameResult']) -> Tuple[str, int, int]:
    """Return ``(CSV text, solved, total)``: camera position (object frame, m), yaw, range."""
    lines = ['t,x_m,y_m,z_m,yaw_deg,range_m,roll_deg,pitch_deg,reason']
    solved = total = 0
    for r in results:
        total += 1
        att = r.attitude or (np.nan, np.nan)
        if r.solution is None:
            lines.append(f'{r.stamp_s:.6f},,,,,,{np.degrees(att[0]):.4f},'
                         f'{np.degrees(att[1]):.4f},"{r.reason}"')
            continue
        solved += 1
        pos = r.solution.camera_position
        lines.append(f'{r.stamp_s:.6f},{pos[0]:.5f},{pos[1]:.5f},{pos[2]:.5f},'
                     f'{np.degrees(r.solution.yaw):.4f},{r.solution.range_m:.5f},'
                     f'{np.degrees(att[0]):.4f},{np.degrees(att[1]):.4f},')
    return '\n'.join(lines) + '\n', solved, total
