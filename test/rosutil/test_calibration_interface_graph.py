"""
Graph test: the same service calls get the same answers from every calibration node.

``calibration``, ``rig_calibration`` and ``lidar_calibration`` run as processes (no sensor
data); each gets one sequence of std_srvs/Trigger calls, as ``ros2 service call`` makes
them, and its transient-local ``<node>/status`` and ``/diagnostics`` are read.
"""
import time

from accelcal_ros.session_interface import STATUS_KEYS
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_srvs.srv import Trigger

NODES = ('calibration', 'rig_calibration', 'lidar_calibration')
LATCHED = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


def _values(status):
    return {kv.key: kv.value for kv in status.values}


def _latest_status(graph, node, timeout=20.0):
    """Return the one status a late joiner gets (transient local, depth 1)."""
    collector = graph.collect(DiagnosticStatus, f'{node}/status', LATCHED)
    messages = collector.wait_for(1, timeout)
    return messages[-1]


def _sequence(graph, node):
    """Call the services in one order; return [(success, message)] and the statuses seen."""
    answers = {}

    def call(label, service):
        reply = graph.call(Trigger, f'{node}/{service}', timeout=30.0)
        answers[label] = (reply.success, reply.message)

    idle = _latest_status(graph, node)
    call('finish_idle', 'finish')
    call('capture_idle', 'capture')
    call('cancel_idle', 'cancel')
    call('start', 'start')
    call('start_again', 'start')
    call('capture_no_data', 'capture')
    call('finish_empty', 'finish')
    running = _latest_status(graph, node)
    call('cancel', 'cancel')
    call('cancel_again', 'cancel')
    ended = _latest_status(graph, node)
    return answers, idle, running, ended


@pytest.mark.graph
def test_every_calibration_node_answers_the_same_sequence_the_same(graph, tmp_path):
    """Refusals, acceptances, status keys and /diagnostics agree across the three nodes."""
    diagnostics = graph.collect(DiagnosticArray, '/diagnostics', 50)
    graph.start('calibration', params={'output_file': str(tmp_path / 'accel.yaml'),
                                       'status_period_s': 0.2})
    graph.start('rig_calibration', params={'output_file': str(tmp_path / 'rig.yaml'),
                                           'capture_dir': str(tmp_path / 'rig_capture'),
                                           'status_period_s': 0.2})
    graph.start('lidar_calibration', params={'output_file': str(tmp_path / 'bs.yaml'),
                                             'status_period_s': 0.2})
    for node in NODES:
        answers, idle, running, ended = _sequence(graph, node)
        ok = {label: success for label, (success, _) in answers.items()}
        assert ok == {'finish_idle': False, 'capture_idle': False, 'cancel_idle': False,
                      'start': True, 'start_again': False, 'capture_no_data': False,
                      'finish_empty': False, 'cancel': True, 'cancel_again': False}, answers
        text = {label: message for label, (_, message) in answers.items()}
        for label in ('finish_idle', 'capture_idle', 'cancel_idle', 'cancel_again'):
            assert 'no calibration session is running' in text[label], text[label]
            assert f'call {node}/start first' in text[label], text[label]
        assert text['start_again'].startswith('a calibration session is already running')
        assert f'{node}/finish' in text['start_again'] and f'{node}/cancel' in text['start_again']
        assert text['finish_empty'].startswith('nothing captured yet: ')
        assert text['finish_empty'].endswith(f'then call {node}/finish')
        assert text['cancel'] == 'calibration cancelled; 0 captures discarded'
        for status, active in ((idle, 'false'), (running, 'true'), (ended, 'false')):
            values = _values(status)
            assert list(values)[:len(STATUS_KEYS)] == list(STATUS_KEYS), list(values)
            assert values['active'] == active, (node, values)
            assert values['captures'] == '0'
            assert status.name.startswith(f'{node}: ')
            assert values['output_file'].startswith(str(tmp_path))
        assert _values(running)['hint'], _values(running)
        assert _values(ended)['last_event'].startswith('refused: cannot cancel: ')
    # /diagnostics: one status of each node, without a session running too.
    deadline = time.monotonic() + 20.0
    seen = set()
    while time.monotonic() < deadline and not seen >= set(NODES):
        seen = {s.name.split(':')[0] for m in diagnostics.snapshot()[0] for s in m.status}
        time.sleep(0.1)
    assert seen >= set(NODES), seen


@pytest.mark.graph
def test_status_period_set_at_run_time_takes_effect(graph):
    """status_period_s is settable at run time, and /diagnostics follows it."""
    graph.start('lidar_calibration', params={'status_period_s': 2.0})
    assert _latest_status(graph, 'lidar_calibration')   # the node is up
    diagnostics = graph.collect(DiagnosticArray, '/diagnostics', 50)
    results = graph.set_parameters('lidar_calibration', {'status_period_s': 0.1})
    assert all(r.successful for r in results), results
    diagnostics.clear()
    start = time.monotonic()
    count, elapsed = 0, 0.0
    while elapsed < 60.0:   # a 2 s period gives at most 1 + elapsed / 2; 0.1 s: 10 a second
        count = len([st for m in diagnostics.snapshot()[0] for st in m.status
                     if st.name == 'lidar_calibration: LiDAR-IMU boresight calibration'])
        elapsed = time.monotonic() - start
        if count > 5 and count > 2 + elapsed / 2.0:
            break
        time.sleep(0.1)
    assert count > 5 and count > 2 + elapsed / 2.0, (count, elapsed)


@pytest.mark.graph
def test_rig_reference_must_be_a_camera_of_the_rig(graph):
    """reference:=cam9 for cam0..cam2: refused at start-up (one line) and at run time."""
    bad = graph.start('rig_calibration', name='rig_bad', params={'reference': 'cam9'})
    assert bad.wait_exit(60.0) == 1
    output = bad.output()
    assert "reference 'cam9' is not one of the cameras cam0, cam1, cam2" in output, output
    assert 'Traceback' not in output
    graph.start('rig_calibration', params={'reference': 'cam1'})
    assert _latest_status(graph, 'rig_calibration')
    results = graph.set_parameters('rig_calibration', {'reference': 'cam9'})
    assert not results[0].successful and 'cam9' in results[0].reason
    assert graph.set_parameters('rig_calibration', {'reference': 'cam2'})[0].successful
