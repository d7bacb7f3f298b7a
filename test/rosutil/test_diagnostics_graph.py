"""
Graph tests: ``/diagnostics`` of the nodes that lacked it or ignored their period.

``cloud_assembler`` reports its counts, warns loudly without a boresight and logs a
failed write at ERROR; ``imu_driver``'s ``diagnostics_period_s`` set at run time changes
the period of its ``/diagnostics``.
"""
import time

from diagnostic_msgs.msg import DiagnosticArray
import pytest
from std_srvs.srv import Trigger


def _statuses(collector, prefix):
    return [s for m in collector.snapshot()[0] for s in m.status if s.name.startswith(prefix)]


def _wait_status(collector, prefix, timeout=20.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        found = _statuses(collector, prefix)
        if found:
            return found[-1]
        time.sleep(0.1)
    raise TimeoutError(f'no /diagnostics status from {prefix} in {timeout} s')


@pytest.mark.graph
def test_cloud_assembler_warns_without_boresight_and_reports_write_failures(graph, tmp_path):
    """WARN status and a loud start line without a boresight; a failed save is an ERROR."""
    diagnostics = graph.collect(DiagnosticArray, '/diagnostics', 50)
    folder = tmp_path / 'out'
    folder.mkdir()
    proc = graph.start('cloud_assembler', params={'output_file': str(folder / 'map.ply')})
    status = _wait_status(diagnostics, 'cloud_assembler: georeferenced')
    values = {kv.key: kv.value for kv in status.values}
    assert status.level == b'\x01' and 'identity boresight' in status.message, status
    assert values['scans'] == '0' and values['boresight'] == 'identity (none given)'
    assert 'NO BORESIGHT GIVEN' in proc.output()
    folder.rmdir()
    folder.write_text('a file where the folder was')
    reply = graph.call(Trigger, 'cloud_assembler/save', timeout=20.0)
    assert not reply.success and reply.message.startswith('cannot write')
    deadline = time.monotonic() + 30.0
    while '[ERROR]' not in proc.output() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert any('[ERROR]' in line and 'cannot write' in line
               for line in proc.output().splitlines()), proc.output()
    diagnostics.clear()
    status = _wait_status(diagnostics, 'cloud_assembler: georeferenced')
    assert status.level == b'\x02' and status.message.startswith('cannot write')


@pytest.mark.graph
def test_driver_diagnostics_period_set_at_run_time_takes_effect(graph):
    """diagnostics_period_s 5 s -> 0.1 s: many more /diagnostics messages per second."""
    diagnostics = graph.collect(DiagnosticArray, '/diagnostics', 50)
    graph.start('imu_driver', params={'backend': 'sim', 'rate_hz': 50.0,
                                      'diagnostics_period_s': 5.0})
    graph.get_parameters('imu_driver', ['diagnostics_period_s'], timeout=30.0)
    results = graph.set_parameters('imu_driver', {'diagnostics_period_s': 0.1})
    assert all(r.successful for r in results), results
    diagnostics.clear()
    start = time.monotonic()
    count, elapsed = 0, 0.0
    while elapsed < 60.0:   # a 5 s period gives at most 1 + elapsed / 5; 0.1 s: 10 a second
        count, elapsed = len(_statuses(diagnostics, 'imu_driver:')), time.monotonic() - start
        if count > 5 and count > 2 + elapsed / 5.0:
            break
        time.sleep(0.1)
    assert count > 5 and count > 2 + elapsed / 5.0, (count, elapsed)
