"""
``/tf_static`` as tf2_ros's ``StaticTransformBroadcaster`` publishes it (ROS side).

QoS: reliable, transient local, keep last 1 (tf2_ros's ``StaticBroadcasterQoS``): a
listener that starts later still gets the transforms. Every :meth:`StaticBroadcaster.send`
publishes *one* ``tf2_msgs/TFMessage`` holding every transform this broadcaster has sent
(a later send of the same child frame replaces it), so the one message kept for late
joiners is always the whole set. Conversions take and give
:class:`~accelcal_ros.frame_tree.FrameTransform` (``v_parent = R v_child + t``, tf2's
convention: ``header.frame_id`` = parent, ``child_frame_id`` = child).
"""
from typing import Dict, List, Sequence

from accelcal_ros.frame_tree import (check_tree, FrameTransform,
                                     rotation_from_quaternion_xyzw)
from geometry_msgs.msg import TransformStamped
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

TF_STATIC_TOPIC = '/tf_static'

STATIC_TF_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                           reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""tf2_ros's static broadcaster and listener QoS."""


def transform_to_msg(transform: FrameTransform, stamp) -> TransformStamped:
    """Return the geometry_msgs/TransformStamped of ``transform`` stamped ``stamp``."""
    msg = TransformStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = transform.parent
    msg.child_frame_id = transform.child
    t = msg.transform.translation
    t.x, t.y, t.z = (float(v) for v in transform.translation)
    q = msg.transform.rotation
    q.x, q.y, q.z, q.w = (float(v) for v in transform.quaternion_xyzw())
    return msg


def msg_to_transform(msg: TransformStamped) -> FrameTransform:
    """Return the :class:`FrameTransform` a TransformStamped stands for (as tf2 reads it)."""
    t, q = msg.transform.translation, msg.transform.rotation
    return FrameTransform(msg.header.frame_id, msg.child_frame_id,
                          rotation_from_quaternion_xyzw([q.x, q.y, q.z, q.w]),
                          [t.x, t.y, t.z])


def transforms_to_message(transforms: Sequence[FrameTransform], stamp) -> TFMessage:
    """Return one TFMessage holding every transform (all stamped ``stamp``)."""
    return TFMessage(transforms=[transform_to_msg(tf, stamp) for tf in transforms])


class StaticBroadcaster:
    """Publish static transforms on ``/tf_static`` the way tf2_ros does (one latched message)."""

    def __init__(self, node) -> None:
        self._node = node
        self._publisher = node.create_publisher(TFMessage, TF_STATIC_TOPIC, STATIC_TF_QOS)
        self._sent: Dict[str, FrameTransform] = {}

    @property
    def transforms(self) -> List[FrameTransform]:
        """Every transform sent so far (the content of the last message)."""
        return list(self._sent.values())

    def send(self, transforms: Sequence[FrameTransform], replace: bool = False) -> None:
        """
        Publish ``transforms`` together with those sent before (``replace``: instead of them).

        The whole set is checked to be one tree first (:func:`check_tree`): a set that is
        not is refused with InputError and nothing is published.
        """
        merged = {} if replace else dict(self._sent)
        for tf in transforms:
            merged[tf.child] = tf
        check_tree(list(merged.values()))
        stamp = self._node.get_clock().now().to_msg()
        self._publisher.publish(transforms_to_message(list(merged.values()), stamp))
        self._sent = merged
