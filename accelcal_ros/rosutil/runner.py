"""
Start-up, executor and shutdown of a node process (``main()`` of every executable: :func:`run`).

Executor: ``events`` (rclpy's ``rclpy.experimental.EventsExecutor``: about half the CPU
per message of the standard executors; falls back to ``single`` where rclpy lacks it),
``single`` (``SingleThreadedExecutor``) or ``multi`` (``MultiThreadedExecutor``). Each
node names its default; the environment variable ``ACCELCAL_EXECUTOR=events|single|multi``
overrides it for every node started from that environment (no parameter: the executor
exists before the node's parameters do).

Shutdown: the runner installs its own SIGINT and SIGTERM handlers (rclpy's are not
installed), which end the spin loop; the node's ``close()`` then stops its threads
while the context is still valid (no ``RCLError`` from a publishing thread), and only
then are the node and the context destroyed. Exit status 0. A second signal while
closing ends the process at once (status 128 + signal number, no clean-up).

Errors a user can cause at start-up (bad parameter, missing device, unreadable file) are
:class:`~accelcal_ros.errors.AccelcalError` (rclpy's parameter exceptions are turned
into one): they are logged as one FATAL line through the node's logger (so they also
reach ``/rosout``), or through a logger named after the executable when the node does not
exist yet, and the process exits with status 1 instead of printing a traceback. rcl's
own errors about the command line (``-p model:=``, ``--params-file /missing.yaml``) are
one such line too (:func:`rcl_argument_error`). After a FATAL line the node lingers until
a ``/rosout`` reader is matched, at most ``ACCELCAL_ROSOUT_WAIT_S`` seconds (default 3:
how long a failed ``ros2 run`` may take to return when nothing reads ``/rosout``).
"""
import contextlib
import os
import re
import signal
import sys
import time
import traceback
from typing import Callable, Optional, Sequence

from accelcal_ros.errors import AccelcalError
import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import (ExternalShutdownException, MultiThreadedExecutor,
                             SingleThreadedExecutor)
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy_impl
from rclpy.node import Node
from rclpy.task import Future

EXECUTOR_ENV = 'ACCELCAL_EXECUTOR'
"""Environment variable that overrides every node's default executor."""

EXECUTORS = ('events', 'single', 'multi')

_SPIN_TIMEOUT_S = 0.1
"""Longest time between two checks of the stop flag (the signal handlers set it)."""


def executor_kind(default: str, environ: Optional[dict] = None) -> str:
    """Return the executor to use: ``$ACCELCAL_EXECUTOR`` if set, else ``default``."""
    value = (os.environ if environ is None else environ).get(EXECUTOR_ENV, '').strip().lower()
    if not value:
        return default
    if value not in EXECUTORS:
        raise AccelcalError(f'{EXECUTOR_ENV}={value!r}: use one of {", ".join(EXECUTORS)} '
                            '(or leave it unset for the node default)')
    return value


def make_executor(kind: str, threads: int = 2):
    """
    Return ``(executor, kind)`` for ``kind`` (events, single or multi).

    ``events`` falls back to ``single`` when this rclpy has no EventsExecutor.
    """
    if kind == 'events':
        try:
            from rclpy.experimental import EventsExecutor
        except ImportError:
            kind = 'single'
        else:
            return EventsExecutor(), 'events'
    if kind == 'multi':
        return MultiThreadedExecutor(num_threads=max(2, threads)), 'multi'
    return SingleThreadedExecutor(), 'single'


class _StopFlag:
    """Set by SIGINT/SIGTERM; a second signal ends the process at once (status 128 + signal)."""

    def __init__(self) -> None:
        self.requested = False

    def handler(self, signum, frame) -> None:
        if self.requested:
            os._exit(128 + signum)
        self.requested = True


def _install_signal_handlers(stop: _StopFlag) -> dict:
    previous = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            previous[sig] = signal.signal(sig, stop.handler)
        except ValueError:  # not the main thread (a node run inside a test thread)
            pass
    return previous


def _restore_signal_handlers(previous: dict) -> None:
    for sig, handler in previous.items():
        signal.signal(sig, handler)


def _spin(executor, kind: str, stop: _StopFlag) -> None:
    """Spin until a signal sets ``stop`` or the context shuts down."""
    context = executor.context
    if kind == 'events':
        # The events executor's spin() neither returns on a signal nor delivered anything
        # in rclpy 7.1.6; spinning on a future that never completes, with a timeout, does.
        never = Future()
        while not stop.requested and context.ok():
            executor.spin_until_future_complete(never, timeout_sec=_SPIN_TIMEOUT_S)
        return
    while not stop.requested and context.ok():
        executor.spin_once(timeout_sec=_SPIN_TIMEOUT_S)


def _node_in_traceback(exc: BaseException) -> Optional[Node]:
    """Return the node whose constructor raised ``exc`` (a frame's ``self``), if any."""
    found = None
    for frame, _ in traceback.walk_tb(exc.__traceback__):
        candidate = frame.f_locals.get('self')
        if isinstance(candidate, Node):
            found = candidate
    return found


def _node_name(node: Optional[Node]) -> Optional[str]:
    try:
        return node.get_name() if node is not None else None
    except Exception:  # noqa: B902 - a node whose construction failed early has no handle
        return None


def _executable_name() -> str:
    return os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else 'accelcal_ros'


ROSOUT_WAIT_S = 3.0
"""Default of ``ACCELCAL_ROSOUT_WAIT_S``: seconds a failing node waits for a ``/rosout`` reader."""


def _rosout_wait_s() -> float:
    """``ACCELCAL_ROSOUT_WAIT_S`` (seconds, 0-60), or :data:`ROSOUT_WAIT_S` if unset or bad."""
    try:
        value = float(os.environ.get('ACCELCAL_ROSOUT_WAIT_S', ROSOUT_WAIT_S))
    except ValueError:
        return ROSOUT_WAIT_S
    return value if 0.0 <= value <= 60.0 else ROSOUT_WAIT_S


def _linger_for_rosout(node: Node, wait_s: Optional[float] = None,
                       delivery_s: float = 1.0) -> None:
    """
    Keep the node alive until ``/rosout`` readers (rqt_console, a recorder) got the line.

    ``/rosout`` is transient-local: a reader matched while the node lives still gets the
    line. A silent publisher on ``/rosout`` with the same QoS tells when this node has
    matched a reader (DDS matching; the graph cache can lag it by seconds); the reader
    matches this node's writers on its own side a little later, hence ``delivery_s`` more
    (1 s: enough on a loaded machine). At most ``wait_s`` (:func:`_rosout_wait_s`) when no
    reader is there.
    """
    wait_s = _rosout_wait_s() if wait_s is None else wait_s
    try:
        from rcl_interfaces.msg import Log
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
        witness = node.create_publisher(Log, '/rosout', qos)
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            if witness.get_subscription_count() > 0:
                time.sleep(delivery_s)
                return
            time.sleep(0.02)
    except Exception:  # noqa: B902 - best effort: the line is on stderr anyway
        pass


def report_fatal(node: Optional[Node], message: str) -> None:
    """
    Log one FATAL line through the node's logger (stderr and ``/rosout``).

    Without a node (or before rclpy is initialised) the line goes through a logger named
    after the executable, or to stderr.
    """
    name = _node_name(node)
    try:
        if name is not None:
            node.get_logger().fatal(message)
            _linger_for_rosout(node)
            return
        rclpy.logging.get_logger(_executable_name()).fatal(message)
    except Exception:  # noqa: B902 - logging itself failed: plain stderr
        print(f'[{name or _executable_name()}] error: {message}', file=sys.stderr, flush=True)


_RCL_WHERE = re.compile(r',? at /\S+?\.c:\d+')


def rcl_argument_error(exc: BaseException) -> AccelcalError:
    """
    Return rcl's error about the command line (``--ros-args``) as one clear line.

    rcl's text (``failed to initialize rcl: Couldn't parse parameter override rule:
    '-p model:='. Error: error not set, at .../arguments.c:352``) loses its source
    locations and empty details and gains how the arguments are written.
    """
    text = ' '.join(str(exc).split())
    text = _RCL_WHERE.sub('', text)
    text = text.replace('. Error: error not set', '').replace('failed to initialize rcl: ', '')
    return AccelcalError(f'bad command-line arguments: {text.rstrip(". ")} (write '
                         '--ros-args -p name:=value, -r from:=to, --params-file FILE.yaml '
                         'with an existing YAML file)')


def _rcl_init(args: Sequence[str]) -> None:
    """``rclpy.init`` whose argument errors (RCLError) become one AccelcalError line."""
    from rclpy.signals import SignalHandlerOptions

    quiet = _quiet_rcl_logger()  # rcl's own "Failed to parse global arguments" line
    try:
        rclpy.init(args=list(args), signal_handler_options=SignalHandlerOptions.NO)
    except _rcl_error() as exc:
        raise rcl_argument_error(exc) from None
    finally:
        quiet()


def _quiet_rcl_logger() -> Callable[[], None]:
    """Silence the ``rcl`` logger below FATAL; return the function that restores it."""
    from rclpy.logging import get_logger_effective_level, LoggingSeverity, set_logger_level

    try:
        level = get_logger_effective_level('rcl')
        set_logger_level('rcl', LoggingSeverity.FATAL)
    except Exception:  # noqa: B902 - logging not ready: rcl's line stays, harmless
        return lambda: None

    def restore() -> None:  # unless --log-level set rcl's level during init
        with contextlib.suppress(Exception):
            if get_logger_effective_level('rcl') == LoggingSeverity.FATAL:
                set_logger_level('rcl', level)
    return restore


def _rcl_error() -> type:
    from rclpy.impl.implementation_singleton import rclpy_implementation

    return rclpy_implementation.RCLError


def rcl_error_line(exc: BaseException) -> str:
    """
    One line for an error of rcl/rmw (starting rclpy or the node): no C source locations.

    Security errors (``ROS_SECURITY_ENABLE``) point to docs/deployment.md.
    """
    text = ' '.join(str(exc).split())
    text = re.sub(r',? at /\S+:\d+', '', text).strip()
    if 'secur' in text.lower():
        text += ' (SROS2: see docs/deployment.md, "Security")'
    return f'cannot start the node: {text}'


def _close(node: Node, built: bool, spinner=None) -> None:
    if built:
        close = getattr(node, 'close', None)
        if close is not None:
            close()
    if spinner is not None:
        # A multi-threaded executor's workers may still run a callback; the executor's
        # shutdown() neither waits for them (rclpy 7) nor keeps the guard condition they
        # trigger ("exception was never retrieved: cannot use Destroyable"): wait for
        # them first, then shut the executor down, and only then destroy the node.
        pool = getattr(spinner, '_executor', None)
        if pool is not None and hasattr(pool, 'shutdown'):
            pool.shutdown(wait=True)
        spinner.shutdown()
    try:
        node.destroy_node()
    except Exception:  # noqa: B902 - a half-built node may fail to destroy: exiting anyway
        pass


def run(node_factory: Callable[[], Node], args: Optional[Sequence[str]] = None,
        threads: int = 2, executor: Optional[str] = None) -> int:
    """
    Create the node with ``node_factory()``, spin it until SIGINT/SIGTERM; return the exit code.

    ``executor`` is the node's default (events, single or multi; ``$ACCELCAL_EXECUTOR``
    overrides it); when not given, ``threads=1`` means single and more threads multi (the
    old interface). ``threads`` is the MultiThreadedExecutor's thread count. A node logs;
    it never draws the offline commands' progress bars (``ACCELCAL_PROGRESS=0`` unless set).
    """
    os.environ.setdefault('ACCELCAL_PROGRESS', '0')

    default = executor or ('single' if threads == 1 else 'multi')
    stop = _StopFlag()
    previous = _install_signal_handlers(stop)
    node = None
    built = False
    spinner = None
    code = 0
    try:
        kind = executor_kind(default)
        _rcl_init(list(args) if args is not None else sys.argv)
        node = node_factory()
        built = True
        spinner, kind = make_executor(kind, threads)
        spinner.add_node(node)
        node.get_logger().debug(f'spinning with the {kind} executor')
        _spin(spinner, kind, stop)
    except (AccelcalError, ParameterException) as exc:
        if node is None:
            node = _node_in_traceback(exc)
        report_fatal(node, str(exc))
        code = 1
    except _rclpy_impl.RCLError as exc:  # rcl/rmw refused (e.g. security settings)
        report_fatal(node, rcl_error_line(exc))
        code = 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            _close(node, built, spinner)
        elif spinner is not None:
            spinner.shutdown()
        if rclpy.ok():
            rclpy.shutdown()
        _restore_signal_handlers(previous)
    return code
