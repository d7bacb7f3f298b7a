"""
The graph across two hosts: network namespaces joined by a veth pair (issue 25).

Host A runs the simulated ADXL345 (``imu_driver``), ``attitude`` and a camera rig
(:mod:`graph_harness.camera_sim`); host B runs ``calibration``, ``stitcher``
(``image_transport:=compressed``) and a probe (:mod:`graph_harness.journey_probe`). Each
host has its own address in a private /24, discovery is
``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET`` (multicast on the link) and every process uses a
UDP-only Fast DDS profile: as between two computers, nothing goes through shared memory.
The calibration journey (captures from A's IMU, the fit, the file, the new calibration
set on A's ``attitude`` over the link) and the panorama (A's frames and attitude stitched
on B) must work. A second test: with LOCALHOST discovery (no multicast) B finds A's nodes
only through ``ROS_STATIC_PEERS`` (networks without multicast). Needs root and ``ip
netns``; skipped otherwise, with the reason.
Everything made is removed at the end, also after a failure.
"""
import json
import os
import signal
import subprocess
import sys

from accelcal_ros.calibration.coverage import recommended_directions, roll_pitch_deg_of
from accelcal_ros.camera.rig import ring_rig, save_rig
from accelcal_ros.sensor.calibration_file import load_calibration
import numpy as np
import pytest

TRUTH_SCALE = np.array([0.928, 0.909, 0.896])
TRUTH_BIAS = np.array([-0.025, -0.037, -0.056])
HERE = os.path.dirname(os.path.abspath(__file__))

UDP_ONLY_PROFILE = """<?xml version="1.0" encoding="UTF-8"?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <transport_descriptors>
    <transport_descriptor>
      <transport_id>udp</transport_id>
      <type>UDPv4</type>
    </transport_descriptor>
  </transport_descriptors>
  <participant profile_name="udp_only" is_default_profile="true">
    <rtps>
      <userTransports>
        <transport_id>udp</transport_id>
      </userTransports>
      <useBuiltinTransports>false</useBuiltinTransports>
    </rtps>
  </participant>
</profiles>
"""
"""Fast DDS over UDP only: what two computers have (shared memory is within one host)."""


@pytest.fixture
def two_hosts():
    """Yield :class:`graph_harness.netns.TwoHosts`; removed afterwards, also on failure."""
    from graph_harness.netns import TwoHosts, unavailable

    reason = unavailable()
    if reason:
        print(f'two-host graph test skipped: {reason}')
        pytest.skip(reason)
    hosts = TwoHosts()
    try:
        yield hosts
    finally:
        hosts.remove()


@pytest.mark.graph
def test_calibration_and_panorama_across_two_hosts(two_hosts, tmp_path):
    from graph_harness.graph import NodeProcess

    profile = tmp_path / 'udp_only.xml'
    profile.write_text(UDP_ONLY_PROFILE)
    env = {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET',
           'FASTRTPS_DEFAULT_PROFILES_FILE': str(profile),
           'PYTHONPATH': os.pathsep.join([HERE, os.environ.get('PYTHONPATH', '')])}
    rig = ring_rig(3, 320, 240, 275.0, 45.0)
    save_rig(tmp_path / 'rig.yaml', rig)
    output = tmp_path / 'calibration.yaml'
    poses = roll_pitch_deg_of(recommended_directions(14)).ravel().tolist()
    a, b = two_hosts.prefix('a'), two_hosts.prefix('b')
    processes = []

    def start(exe, prefix, params=None, argv=None):
        proc = NodeProcess(exe, params, log_dir=tmp_path, prefix=prefix, env=env, argv=argv)
        processes.append(proc)
        return proc

    try:
        start('imu_driver', a, {'backend': 'sim', 'rate_hz': 100.0, 'seed': 2,
                                'sim.poses_deg': poses, 'sim.dwell_s': 1.0,
                                'sim.move_s': 0.4})
        attitude = start('attitude', a)
        start('camera_sim', a, argv=[sys.executable, '-m', 'graph_harness.camera_sim',
                                     '--rig', str(tmp_path / 'rig.yaml'), '--rate', '5',
                                     '--transport', 'compressed'])
        calibration = start('calibration', b, {'output_file': str(output),
                                               'min_still_s': 0.7})
        stitcher = start('stitcher', b, {'rig_file': str(tmp_path / 'rig.yaml'),
                                         'width': 720, 'height': 480,
                                         'image_transport': 'compressed'})
        before = two_hosts.link_bytes('b')
        probe = subprocess.run(
            [*b, sys.executable, '-m', 'graph_harness.journey_probe', '--positions', '14',
             '--timeout', '60', '--log-dir', str(tmp_path)],
            env=dict(os.environ, **env), capture_output=True, text=True, timeout=150)
        after = two_hosts.link_bytes('b')
        lines = [line for line in probe.stdout.splitlines() if line.startswith('{')]
        logs = '\n'.join(f'--- {p.log_path}\n{p.output()[-1500:]}' for p in processes)
        assert lines, f'probe printed nothing: {probe.stderr[-2000:]}\n{logs}'
        result = json.loads(lines[-1])
        print(f'two-host journey: {json.dumps(result)}; link bytes B {before} -> {after}')
        assert 'error' not in result, (result, logs)
        for proc in (attitude, calibration, stitcher):
            assert proc.proc.poll() is None, proc.output()
    finally:
        for proc in processes:                  # all at once, then wait for each
            if proc.proc.poll() is None:
                proc.proc.send_signal(signal.SIGINT)
        for proc in processes:
            proc.stop()

    # the calibration journey: captures of A's IMU on B, the fit, A's attitude updated
    assert result['start'][0], result
    assert result['positions'] >= 14, result
    assert result['finish'][0] and str(output) in result['finish'][1], result
    record = load_calibration(output)
    np.testing.assert_allclose(record.sensor_model.scale, TRUTH_SCALE, atol=1.5e-3)
    np.testing.assert_allclose(record.sensor_model.bias, TRUTH_BIAS, atol=1.5e-3)
    np.testing.assert_allclose(result['attitude_scale'], record.sensor_model.scale,
                               atol=1e-9)
    # the panorama: A's JPEG frames and attitude stitched on B
    panoramas = result['panoramas']
    assert panoramas['count'] >= 3, result
    assert panoramas['size'] == [720, 480, 'bgr8']
    assert panoramas['covered_max'] > 0.1, result
    # the traffic went over the link (IMU at 100 Hz, three JPEG streams at 5 Hz)
    received = after[1] - before[1]
    assert received > 1e6, (before, after)


@pytest.mark.graph
def test_static_peers_without_multicast_discovery(two_hosts, tmp_path):
    """LOCALHOST discovery (no multicast): B finds A's IMU only with ROS_STATIC_PEERS."""
    from graph_harness.graph import NodeProcess

    profile = tmp_path / 'udp_only.xml'
    profile.write_text(UDP_ONLY_PROFILE)
    local = {'FASTRTPS_DEFAULT_PROFILES_FILE': str(profile),
             'PYTHONPATH': os.pathsep.join([HERE, os.environ.get('PYTHONPATH', '')]),
             'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    driver = NodeProcess('imu_driver', {'backend': 'sim', 'rate_hz': 100.0},
                         log_dir=tmp_path, prefix=two_hosts.prefix('a'), env=local)
    try:
        counts = {}
        for label, variables in (('no peer', local),
                                 ('static peer', dict(local, ROS_STATIC_PEERS=two_hosts
                                                      .addresses['a']))):
            probe = subprocess.run(
                [*two_hosts.prefix('b'), sys.executable, '-m', 'graph_harness.count_topic',
                 'imu/data_raw', 'sensor_msgs/msg/Imu', '--count', '50',
                 '--timeout', '20' if label == 'static peer' else '3'],
                env=dict(os.environ, **variables), capture_output=True, text=True, timeout=60)
            lines = [line for line in probe.stdout.splitlines() if line.startswith('{')]
            assert lines, probe.stderr[-2000:]
            counts[label] = json.loads(lines[-1])['count']
        assert driver.proc.poll() is None, driver.output()
    finally:
        driver.stop()
    print(f'static peers across two hosts: {counts}')
    assert counts['no peer'] == 0 and counts['static peer'] >= 50, counts


def _namespaces():
    listing = subprocess.run(['ip', 'netns', 'list'], capture_output=True, text=True)
    return {line.split()[0] for line in listing.stdout.splitlines() if line.strip()}


def test_namespaces_are_removed_also_those_of_killed_runs(two_hosts):
    """remove() deletes both namespaces (and the veth); a dead run's leftovers go too."""
    from graph_harness.netns import remove_stale

    made = set(two_hosts.names.values())
    assert made <= _namespaces()
    assert two_hosts.run('a', 'ip', 'addr', 'show', two_hosts.links['a']).returncode == 0
    two_hosts.remove()
    assert not made & _namespaces()
    stale = 'accelcal-99999999-abcdef-a'         # no such pid: a killed run's namespace
    subprocess.run(['ip', 'netns', 'add', stale], check=True)
    try:
        remove_stale()
        assert stale not in _namespaces()
    finally:
        subprocess.run(['ip', 'netns', 'del', stale], capture_output=True)
