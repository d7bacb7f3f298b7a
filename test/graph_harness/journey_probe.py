"""
The calibration journey and the panorama, seen from one host (a probe process).

``python -m graph_harness.journey_probe --positions 14 --timeout 60`` talks to a graph
whose nodes may run on other hosts (the two-host graph test runs it in host B):
``calibration/start``, waits for ``--positions`` captured positions on
``calibration/status``, ``calibration/finish``, then reads ``calibration.scale`` of the
``attitude`` node until the calibration arrived there; meanwhile it collects
``panorama``. Prints one JSON line: the service replies, the positions, the attitude's
scale, the panoramas (count, size, largest covered fraction, median latency from the
camera stamp) or ``error``. A probe process of its own, because one process's Fast DDS
keeps to the network namespace it first ran in.
"""
import argparse
import json
import statistics
import time


def _values(msg):
    return {kv.key: kv.value for kv in msg.values}


def journey(graph, positions, timeout, result):
    """Run the journey on ``graph`` (a :class:`~.graph.Graph`), filling ``result``."""
    from diagnostic_msgs.msg import DiagnosticStatus
    from std_srvs.srv import Trigger

    status = graph.collect(DiagnosticStatus, 'calibration/status', 10)
    deadline = time.monotonic() + timeout
    reply = graph.call(Trigger, 'calibration/start', timeout=timeout)
    result['start'] = [reply.success, reply.message]
    got = 0
    while time.monotonic() < deadline and got < positions:
        time.sleep(0.3)
        messages, _ = status.snapshot()
        if messages:
            got = int(_values(messages[-1]).get('captures', 0) or 0)
    result['positions'] = got
    reply = graph.call(Trigger, 'calibration/finish', timeout=30.0)
    result['finish'] = [reply.success, reply.message]
    scale = None
    while time.monotonic() < deadline + 15.0:
        scale = graph.get_parameters('attitude', ['calibration.scale'],
                                     timeout=15.0)['calibration.scale']
        if scale is not None and list(scale) != [1.0, 1.0, 1.0]:
            break
        time.sleep(0.3)
    result['attitude_scale'] = None if scale is None else [float(v) for v in scale]


def panorama_summary(collector):
    """Count, size, largest covered fraction and median latency (ms) of the panoramas."""
    import numpy as np

    messages, receive_times = collector.snapshot()
    summary = {'count': len(messages)}
    if messages:
        last = messages[-1]
        summary['size'] = [last.width, last.height, last.encoding]
        covered = []
        for msg in messages[-10:]:
            pixels = np.frombuffer(bytes(msg.data), np.uint8).reshape(msg.height, msg.step)
            covered.append(float((pixels.reshape(msg.height, msg.width, -1).max(axis=2)
                                  > 0).mean()))
        summary['covered_max'] = max(covered)
        latency = [t - (m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec)
                   for m, t in zip(messages, receive_times)]
        summary['latency_ms'] = 1e3 * statistics.median(latency)
    return summary


def main(argv=None):
    """Run the probe; print the JSON result."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--positions', type=int, default=14)
    parser.add_argument('--timeout', type=float, default=60.0)
    parser.add_argument('--log-dir', default='.')
    args = parser.parse_args(argv)

    from graph_harness.graph import Graph
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Image

    result, panoramas = {}, None
    graph = Graph(log_dir=args.log_dir, name='journey_probe')
    try:
        panoramas = graph.collect(Image, 'panorama', QoSProfile(
            depth=2, reliability=ReliabilityPolicy.RELIABLE))
        journey(graph, args.positions, args.timeout, result)
        deadline = time.monotonic() + 15.0
        while time.monotonic() < deadline and len(panoramas.snapshot()[0]) < 3:
            time.sleep(0.2)
        result['panoramas'] = panorama_summary(panoramas)
    except Exception as exc:  # the process boundary: report it in the JSON
        result['error'] = f'{type(exc).__name__}: {exc}'
        if panoramas is not None:
            result['panoramas'] = panorama_summary(panoramas)
    finally:
        graph.close()
    print(json.dumps(result), flush=True)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
