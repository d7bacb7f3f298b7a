"""Graph test: ``calibration_frames`` on /tf_static, received as a late joiner, as tf2 reads it."""
import time

from accelcal_ros.boresight_file import load_boresight
from accelcal_ros.camera.rig import load_rig, rig_to_mapping, ring_rig
from accelcal_ros.fileio import write_text_atomic
from accelcal_ros.frame_tree import check_tree, to_ancestor
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rotation_from_rpy_radians
from accelcal_ros.rosutil.static_tf import msg_to_transform, STATIC_TF_QOS
from accelcal_ros.textformats import dump_yaml
import numpy as np
import pytest
from tf2_msgs.msg import TFMessage

TFMESSAGE_HASH = 'RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087'
"""tf2_msgs/msg/TFMessage's type hash in ROS 2 Jazzy (what `ros2 topic info -v` shows)."""

MOUNT_XYZ = [0.1, -0.05, 0.2]
MOUNT_RPY_DEG = [3.0, -2.0, 90.0]
LEVER = [0.3, -0.1, 0.25]


def _write_boresight(path, rpy_deg):
    r = rotation_from_rpy_radians(*np.radians(rpy_deg))
    write_text_atomic(path, dump_yaml({'R': [float(v) for v in r.reshape(-1)],
                                       'rpy_deg': [float(v) for v in rpy_deg]}))


def _wait(predicate, timeout=30.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    return predicate()


def _latest(collector):
    messages = collector.snapshot()[0]
    return messages[-1] if messages else None


@pytest.mark.graph
def test_late_joiner_gets_one_connected_tree_equal_to_the_files(graph, tmp_path):
    """Vectors in lidar_link and every camera frame reach base_link as the files' math says."""
    imu_to_camera = rotation_from_rpy_radians(0.1, -0.2, 0.3) @ DEFAULT_IMU_TO_CAMERA
    rig = rig_to_mapping(ring_rig(3, mount_error_deg=1.0, seed=3,
                                  names=['front', 'right', 'left'], imu_to_camera=imu_to_camera))
    rig['cameras'][1]['t_m'] = [0.12, -0.03, 0.04]     # t_01: X_1 = R_01 X_0 + t_01
    write_text_atomic(tmp_path / 'rig.yaml', dump_yaml(rig))
    _write_boresight(tmp_path / 'boresight.yaml', [1.0, -2.0, 45.0])
    proc = graph.start('calibration_frames', params={
        'rig_file': str(tmp_path / 'rig.yaml'), 'boresight_file': str(tmp_path / 'boresight.yaml'),
        'lidar_lever_arm_m': LEVER, 'imu_mount_xyz_m': MOUNT_XYZ,
        'imu_mount_rpy_deg': MOUNT_RPY_DEG, 'poll_period_s': 0.2})
    # join late: only once the publisher is in the graph (it publishes before it spins)
    assert _wait(lambda: graph.node.count_publishers('/tf_static') > 0), proc.output()
    info = graph.node.get_publishers_info_by_topic('/tf_static')
    assert str(info[0].topic_type_hash) == TFMESSAGE_HASH
    collector = graph.collect(TFMessage, '/tf_static', qos=STATIC_TF_QOS)
    msg = _wait(lambda: _latest(collector))
    assert msg is not None, proc.output()
    transforms = [msg_to_transform(m) for m in msg.transforms]
    assert check_tree(transforms) == 'base_link'         # connected: all reach base_link
    frames = {t.child for t in transforms}
    assert frames == {'imu_link', 'lidar_link', 'front_optical_frame',
                      'right_optical_frame', 'left_optical_frame'}

    # the files' math, written out independently of the node
    rig = load_rig(tmp_path / 'rig.yaml')
    mount = rotation_from_rpy_radians(*np.radians(MOUNT_RPY_DEG))
    boresight = load_boresight(tmp_path / 'boresight.yaml')
    rng = np.random.default_rng(0)
    v = rng.normal(size=3)
    r, t = to_ancestor(transforms, 'lidar_link', 'base_link')
    expected = mount @ (boresight @ v + LEVER) + MOUNT_XYZ          # p_imu = R p_L + l
    assert np.abs(r @ v + t - expected).max() < 1e-9
    for cam in rig.cameras:
        r, t = to_ancestor(transforms, f'{cam.name}_optical_frame', 'base_link')
        # v_i = R_0i v_0 + t_0i and v_0 = imu_to_camera v_imu
        #   =>  v_imu = M^T R_0i^T (v_i - t_0i)
        t_0i = np.zeros(3) if cam.t is None else cam.t
        expected = mount @ (rig.imu_to_camera.T @ (cam.R.T @ (v - t_0i))) + MOUNT_XYZ
        assert np.abs(r @ v + t - expected).max() < 1e-9, cam.name

    # a new boresight file is published again, without a restart
    _write_boresight(tmp_path / 'boresight.yaml', [0.0, 0.0, -30.0])
    new_r = rotation_from_rpy_radians(0.0, 0.0, np.radians(-30.0))

    def updated():
        latest = _latest(collector)
        tfs = {m.child_frame_id: msg_to_transform(m) for m in latest.transforms}
        return np.abs(tfs['lidar_link'].rotation - new_r).max() < 1e-9 and len(tfs) == 5
    assert _wait(updated), proc.output()

    # a broken file is reported, and the good set stays the one late joiners get
    (tmp_path / 'boresight.yaml').write_text('R: [1, 2, 3]\n')
    assert _wait(lambda: 'not usable' in proc.output()), proc.output()
    late = graph.collect(TFMessage, '/tf_static', qos=STATIC_TF_QOS)
    msg = _wait(lambda: _latest(late))
    tfs = {m.child_frame_id: msg_to_transform(m) for m in msg.transforms}
    assert len(tfs) == 5 and np.abs(tfs['lidar_link'].rotation - new_r).max() < 1e-9

    # run time: an invalid frame name is refused with the reason, a valid one republishes
    # (with the files usable again: a change that cannot build the tree is refused too)
    _write_boresight(tmp_path / 'boresight.yaml', [0.0, 0.0, -30.0])
    (result,) = graph.set_parameters('calibration_frames', {'lidar_frame': '/velodyne'})
    assert not result.successful and 'leading' in result.reason
    (result,) = graph.set_parameters('calibration_frames', {'lidar_frame': 'velodyne'})
    assert result.successful, result.reason

    def renamed():
        children = {m.child_frame_id for m in _latest(late).transforms}
        return 'velodyne' in children and 'lidar_link' not in children
    assert _wait(renamed), proc.output()
    assert proc.stop() == 0


@pytest.mark.graph
def test_bad_files_stop_the_node_with_one_reason_before_publishing(graph, tmp_path):
    """Not a rotation, duplicate camera names, boresight without R: exit 1, one line, no tf."""
    rig = rig_to_mapping(ring_rig(2))
    rig['cameras'][1]['R'] = [1, 0, 0, 0, 2, 0, 0, 0, 1]
    write_text_atomic(tmp_path / 'not_rotation.yaml', dump_yaml(rig))
    rig = rig_to_mapping(ring_rig(2))
    rig['cameras'][1]['name'] = rig['cameras'][0]['name']
    write_text_atomic(tmp_path / 'duplicate.yaml', dump_yaml(rig))
    write_text_atomic(tmp_path / 'no_r.yaml', dump_yaml({'rpy_std_deg': [0.1, 0.1, 0.1]}))
    cases = [({'rig_file': str(tmp_path / 'not_rotation.yaml')}, 'not a rotation'),
             ({'rig_file': str(tmp_path / 'duplicate.yaml')}, 'unique'),
             ({'boresight_file': str(tmp_path / 'no_r.yaml')}, 'neither R'),
             ({'lidar_frame': '/lidar'}, 'leading')]
    procs = [graph.start('calibration_frames', params=p, name=f'bad{i}')
             for i, (p, _) in enumerate(cases)]
    for proc, (_, reason) in zip(procs, cases):
        assert proc.wait_exit(timeout=60.0) == 1, proc.output()
        out = proc.output()
        assert reason in out and 'Traceback' not in out, out
        assert 'published' not in out, out
