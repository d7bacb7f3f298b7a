"""
Every node executable stops cleanly on SIGINT and SIGTERM, cycle after cycle.

Each node is started as ``ros2 run`` starts it (with the few parameters it needs: the sim
driver backend, a rig file for the stitcher), waited for until its parameter service
answers (it is spinning), then stopped with SIGINT or SIGTERM, alternately: exit status
0 and no exception line in its output (no traceback, no rclpy "exception was never
retrieved" from an executor thread). ``ACCELCAL_SHUTDOWN_CYCLES`` sets the number of
cycles per node (default 2: one of each signal).
"""
import os
import re
import signal

from accelcal_ros.node_params import NODE_PARAMS
import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CYCLES = int(os.environ.get('ACCELCAL_SHUTDOWN_CYCLES', '2'))
NEEDS = {
    'imu_driver': {'backend': 'sim'},
    'stitcher': {'rig_file': os.path.join(REPO, 'config', 'rig_example.yaml')},
}
BAD_LINE = re.compile(r'Traceback|Exception|exception|Error:|never retrieved')


@pytest.mark.graph
@pytest.mark.parametrize('node', sorted(NODE_PARAMS))
def test_node_stops_cleanly_on_sigint_and_sigterm(graph, node):
    """Exit 0 and not one exception line, for SIGINT and SIGTERM alike."""
    for cycle in range(CYCLES):
        sig = (signal.SIGINT, signal.SIGTERM)[cycle % 2]
        proc = graph.start(node, params=NEEDS.get(node), name=f'{node}_{cycle}')
        for attempt in range(3):   # a first request can be lost while discovery settles
            try:
                graph.get_parameters(node, ['use_sim_time'], timeout=30.0)
                break
            except TimeoutError:
                assert proc.proc.poll() is None, proc.output()
                if attempt == 2:
                    raise
        proc.proc.send_signal(sig)
        code = proc.wait_exit(timeout=30.0)
        out = proc.output()
        bad = [line for line in out.splitlines() if BAD_LINE.search(line)]
        assert code == 0 and not bad, f'{node} {sig.name}: exit {code}\n{out}'
        graph.processes.remove(proc)
        proc.stop()
