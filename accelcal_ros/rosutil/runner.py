"""
Start-up and shutdown of a node process: ``main()`` of every executable calls :func:`run`.

Errors a user can cause at start-up (bad parameter, missing device, unreadable file) are
:class:`~accelcal_ros.errors.AccelcalError`: they are logged as one clear line and the
process exits with status 1 instead of printing a traceback. Ctrl-C exits quietly.
"""
import sys

from accelcal_ros.errors import AccelcalError
import rclpy
from rclpy.executors import (ExternalShutdownException, MultiThreadedExecutor,
                             SingleThreadedExecutor)


def run(node_factory, args=None, threads=2):
    """
    Create the node with ``node_factory()`` and spin it until shutdown; returns exit code.

    ``threads=1`` spins a SingleThreadedExecutor (about half the CPU per message of a
    MultiThreadedExecutor in rclpy: the choice for high-rate subscribers).
    """
    rclpy.init(args=args if args is not None else sys.argv)
    node = None
    code = 0
    try:
        node = node_factory()
        executor = (SingleThreadedExecutor() if threads == 1
                    else MultiThreadedExecutor(num_threads=threads))
        executor.add_node(node)
        executor.spin()
    except AccelcalError as exc:
        name = getattr(node, 'get_name', lambda: 'accelcal_ros')()
        print(f'[{name}] error: {exc}', file=sys.stderr, flush=True)
        code = 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            close = getattr(node, 'close', None)
            if close is not None:
                close()
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return code
