"""Conversions between builtin_interfaces/Time and float seconds (no rclpy import)."""


def stamp_to_seconds(stamp):
    """Float seconds of a ``builtin_interfaces/Time``-like object (sec, nanosec)."""
    return stamp.sec + stamp.nanosec * 1e-9


def seconds_to_stamp(seconds, stamp_type):
    """Build a ``stamp_type()`` (e.g. builtin_interfaces.msg.Time) holding ``seconds``."""
    total_ns = int(round(seconds * 1e9))
    stamp = stamp_type()
    stamp.sec, stamp.nanosec = divmod(total_ns, 1_000_000_000)
    return stamp
