"""Header stamps: float seconds to and from builtin_interfaces/Time, and the order rule."""
from typing import Optional


def stamp_to_seconds(stamp):
    """Float seconds of a ``builtin_interfaces/Time``-like object (sec, nanosec)."""
    return stamp.sec + stamp.nanosec * 1e-9


def seconds_to_stamp(seconds, stamp_type):
    """Build a ``stamp_type()`` (e.g. builtin_interfaces.msg.Time) holding ``seconds``."""
    total_ns = int(round(seconds * 1e9))
    stamp = stamp_type()
    stamp.sec, stamp.nanosec = divmod(total_ns, 1_000_000_000)
    return stamp


TIME_JUMP_BACK_S = 1.0
"""A stamp this far (s) or more before the previous one is the clock jumping back (a bag
played again, a simulation restarted: what tf2 clears its buffer for), not a late sample."""

USE = 'use'
UNSTAMPED = 'unstamped'
OUT_OF_ORDER = 'out_of_order'
JUMPED_BACK = 'time_jump'


class StampOrder:
    """
    The order rule for one stream of header stamps (s), shared by the IMU consumers.

    :meth:`check` returns, for each message's stamp:

    * :data:`USE`: after the previous stamp (the first is always used);
    * :data:`UNSTAMPED`: exactly 0 (``sec = nanosec = 0``, a publisher that does not stamp):
      skip it; it is not a time;
    * :data:`OUT_OF_ORDER`: not after the previous stamp but less than
      :data:`TIME_JUMP_BACK_S` before it (a repeated stamp, a late sample, two publishers
      on one topic): skip it; a filter fed it would step back in time;
    * :data:`JUMPED_BACK`: :data:`TIME_JUMP_BACK_S` or more before the previous stamp: use
      it and restart what depends on time (the stream starts again from here).

    ``jump_s`` holds the size of the last jump back (s), ``skipped`` how many stamps were
    unstamped or out of order so far. A verdict is also the suffix of
    its drop kind (``imu_unstamped``, ``imu_out_of_order``, ``imu_time_jump``).
    """

    __slots__ = ('last', 'jump_s', 'skipped')

    def __init__(self) -> None:
        self.last: Optional[float] = None
        self.jump_s = 0.0
        self.skipped = 0

    def check(self, t: float) -> str:
        """Return :data:`USE`, :data:`UNSTAMPED`, :data:`OUT_OF_ORDER` or :data:`JUMPED_BACK`."""
        if t == 0.0:
            self.skipped += 1
            return UNSTAMPED
        last = self.last
        if last is None or t > last:
            self.last = t
            return USE
        if last - t < TIME_JUMP_BACK_S:
            self.skipped += 1
            return OUT_OF_ORDER
        self.last = t
        self.jump_s = last - t
        return JUMPED_BACK

    def reset(self) -> None:
        """Forget the previous stamp (a new session)."""
        self.last = None

    def reason(self, verdict: str, topic: str, restarts: str) -> str:
        """Return the log line for a ``verdict`` other than :data:`USE` on ``topic``."""
        if verdict == UNSTAMPED:
            return (f'{topic} message with header stamp 0 skipped (its publisher does not '
                    'stamp it)')
        if verdict == OUT_OF_ORDER:
            return (f'{topic} message skipped: its header stamp is not after the previous '
                    'one (a repeated or late stamp, or two publishers on one topic?)')
        return (f'{topic} header stamps jumped back by {self.jump_s:.3f} s (a bag played '
                f'again, a simulation restarted?): {restarts}')
