"""Vectorised Imu decoding equals rosbags' message-by-message deserialisation."""
from accelcal_ros.recording import convert
from accelcal_ros.recording.bag import BagReader
from accelcal_ros.recording.sim_bags import bag_path, FORMATS
from accelcal_ros.recording.streams import read_imu
from accelcal_ros.recording.writer import BagWriter
import numpy as np
import pytest


@pytest.mark.parametrize('fmt', FORMATS)
@pytest.mark.parametrize('mixed_frames', (False, True))
def test_fast_imu_decoding_matches_deserialisation(tmp_path, fmt, mixed_frames):
    """Stamps, frame, force and rate agree; mixed frame_id lengths use the slow path."""
    rng = np.random.default_rng(1)
    accel = rng.normal(0, 5, (60, 3))
    gyro = rng.normal(0, 1, (60, 3))
    path = bag_path(tmp_path, 'imu', fmt)
    with BagWriter(path, fmt) as writer:
        writer.add_topic('/imu', 'sensor_msgs/Imu')
        for k in range(60):
            ns = 1_600_000_000_123_456_789 + k * 5_000_017
            frame = 'imu_link' if not mixed_frames or k % 2 else 'imu'
            writer.write('/imu', ns, writer.imu_message(ns, accel[k], frame, gyro[k]))
    with BagReader(path) as bag:
        raws = [m.raw for m in bag.messages(['/imu'], decode=())]
        slow = [m.msg for m in bag.messages(['/imu'])]
        fast = convert.imu_arrays_from_raw(raws, bag.is_ros1)
        stream = read_imu(bag, None)
    np.testing.assert_array_equal(stream.accel, accel)
    np.testing.assert_array_equal(stream.gyro, gyro)
    header = np.array([m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in slow])
    assert stream.epoch_ns == header[0]
    np.testing.assert_allclose(stream.t, (header - header[0]) / 1e9, rtol=0, atol=1e-12)
    if mixed_frames:
        assert fast is None
    else:
        np.testing.assert_array_equal(fast['header_ns'], header)
        np.testing.assert_array_equal(fast['accel'], accel)
        assert fast['frame_id'] == 'imu_link' and fast['gyro_provided']
