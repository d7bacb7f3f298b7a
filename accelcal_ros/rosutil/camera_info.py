"""
Intrinsics from ``camera_info`` topics at start-up (ROS side; the stitcher's option).

:func:`rig_from_camera_info` waits (spinning the node on a private executor, before the
node's own executor takes it) for one sensor_msgs/CameraInfo on each topic, turns each into
a :class:`~accelcal_ros.camera.model.CameraModel` and returns the rig with those intrinsics
(:func:`accelcal_ros.camera.camera_info.rig_with_models`: each must have the size of the
camera's images). Best effort depth 1, so it matches every driver's publisher.
"""
import time
from typing import Sequence

from accelcal_ros.camera.camera_info import rig_with_models
from accelcal_ros.camera.model import CameraModel
from accelcal_ros.camera.rig import Rig
from accelcal_ros.errors import InputError
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo

CAMERA_INFO_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                             reliability=ReliabilityPolicy.BEST_EFFORT)


def rig_from_camera_info(node, rig: Rig, topics: Sequence[str], timeout_s: float) -> Rig:
    """Return ``rig`` with the intrinsics of the first CameraInfo on each of ``topics``."""
    if len(topics) != len(rig):
        raise InputError(f'camera_info_topics has {len(topics)} topic(s) but the rig has '
                         f'{len(rig)} cameras ({", ".join(rig.names)})')
    received = {}
    subs = [node.create_subscription(CameraInfo, topic,
                                     lambda msg, i=i: received.setdefault(i, msg),
                                     CAMERA_INFO_QOS)
            for i, topic in enumerate(topics)]
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    deadline = time.monotonic() + timeout_s
    try:
        while len(received) < len(topics) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
    finally:
        executor.remove_node(node)
        executor.shutdown()
        for sub in subs:
            node.destroy_subscription(sub)
    missing = [t for i, t in enumerate(topics) if i not in received]
    if missing:
        raise InputError(f'no CameraInfo within {timeout_s:g} s on {", ".join(missing)}: '
                         'start the camera drivers, or leave camera_info_topics empty to '
                         'use the K and D of the rig file')
    models = []
    for i, topic in enumerate(topics):
        msg = received[i]
        try:
            models.append(CameraModel.from_camera_info(msg.k, msg.d, msg.distortion_model,
                                                       msg.width, msg.height))
        except InputError as exc:
            raise InputError(f'{topic}: {exc}') from None
    resolved = [node.resolve_topic_name(t) for t in topics]
    return rig_with_models(rig, models, resolved)
