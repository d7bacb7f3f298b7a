"""
``/diagnostics`` for every node: the publisher, a re-timable period, status construction.

Every node publishes diagnostic_msgs/DiagnosticArray on ``/diagnostics`` (the topic
diagnostic_aggregator and rqt_robot_monitor read), one DiagnosticStatus named
``<node>: <what>`` per thing it watches.
"""
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue


def diagnostics_publisher(node):
    """Return the node's ``/diagnostics`` publisher (diagnostic_msgs/DiagnosticArray)."""
    return node.create_publisher(DiagnosticArray, '/diagnostics', 10)


def publish_diagnostics(node, publisher, statuses):
    """Publish ``statuses`` (DiagnosticStatus list) on ``/diagnostics``, stamped now."""
    msg = DiagnosticArray(status=list(statuses))
    msg.header.stamp = node.get_clock().now().to_msg()
    publisher.publish(msg)


def diagnostic_status(name, hardware_id, level, message, values):
    """Return a DiagnosticStatus (level 0 OK, 1 WARN, 2 ERROR) with ``values`` as KeyValues."""
    status = DiagnosticStatus(name=name, hardware_id=hardware_id, message=message)
    status.level = bytes([int(level)])
    status.values = [KeyValue(key=str(k), value=str(v)) for k, v in values.items()]
    return status


class PeriodicTimer:
    """A node timer whose period can be changed at run time (a parameter that takes effect)."""

    def __init__(self, node, period_s, callback):
        self._node = node
        self._callback = callback
        self._timer = None
        self.set_period(period_s)

    def set_period(self, period_s):
        """Restart the timer with ``period_s`` seconds."""
        if self._timer is not None:
            self._node.destroy_timer(self._timer)
        self._timer = self._node.create_timer(float(period_s), self._callback)
