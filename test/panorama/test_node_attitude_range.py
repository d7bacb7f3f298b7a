"""Graph test: the ``stitcher`` refuses attitudes that are not one (roll 1e300, pitch 4 rad)."""
import time

from accelcal_ros.camera.rig import ring_rig, save_rig
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA
from accelcal_ros.rosutil.images import array_to_image_msg
from accelcal_ros.rosutil.stamps import seconds_to_stamp
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3Stamped
import numpy as np
import pytest
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image

pytestmark = pytest.mark.graph


def _rejected(diag):
    counts = [int(kv.value) for msg in diag.snapshot()[0] for status in msg.status
              for kv in status.values if kv.key == 'rejected_attitudes']
    return max(counts, default=0)


def test_stitcher_publishes_nothing_for_roll_1e300_and_counts_it(graph, tmp_path):
    """Frames with only absurd attitudes: no panorama, the count in /diagnostics, one log."""
    save_rig(tmp_path / 'rig.yaml', ring_rig(2, 64, 48, 55.0, 45.0,
                                             imu_to_camera=DEFAULT_IMU_TO_CAMERA))
    proc = graph.start('stitcher', params={'rig_file': str(tmp_path / 'rig.yaml'),
                                           'width': 180, 'height': 120,
                                           'image_reliability': 'best_effort'})
    pubs = [graph.node.create_publisher(Image, f'cam{i}/image_raw', qos_profile_sensor_data)
            for i in range(2)]
    att = graph.node.create_publisher(Vector3Stamped, 'attitude', qos_profile_sensor_data)
    panoramas = graph.collect(Image, 'panorama')
    diag = graph.collect(DiagnosticArray, '/diagnostics', 50)
    image = np.full((48, 64, 3), 128, np.uint8)
    bad = [(1e300, 0.0), (0.0, 4.0), (float('nan'), 0.0)]
    start = time.monotonic()
    deadline = start + 60.0
    k = 0
    while time.monotonic() < deadline and _rejected(diag) < 6:
        now = time.time()
        msg = Vector3Stamped()
        msg.header.stamp = seconds_to_stamp(now, Time)
        msg.vector.x, msg.vector.y = bad[k % len(bad)]
        att.publish(msg)
        for pub in pubs:
            header = Image().header
            header.stamp = seconds_to_stamp(now, Time)
            pub.publish(array_to_image_msg(image, 'bgr8', Image, header))
        k += 1
        time.sleep(0.1)
    assert _rejected(diag) >= 6, proc.output()
    assert not panoramas.snapshot()[0]
    out = proc.output()
    # logged once per 10 s (the DropCounter's throttle), then counted, whatever the load
    elapsed = time.monotonic() - start
    assert 1 <= out.count('attitude rejected: ') <= 1 + int(elapsed // 10.0), out
    assert 'outside roll +-pi, pitch +-pi/2' in out or 'not finite' in out

    def drops():
        counts = [int(kv.value) for msg in diag.snapshot()[0] for status in msg.status
                  for kv in status.values if status.name == 'stitcher: dropped messages'
                  and kv.key == 'attitudes_dropped']
        return max(counts, default=0)

    deadline = time.monotonic() + 30.0   # published every second: the one home of the count
    while drops() < 6 and time.monotonic() < deadline:
        time.sleep(0.1)
    assert drops() >= 6, proc.output()
    assert proc.proc.poll() is None
