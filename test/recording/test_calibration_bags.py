"""calibrate / apply / attitude / record on bags in the three formats, against the CSV path."""
from accelcal_ros.cli import main
from accelcal_ros.recording.bag import BagReader
from accelcal_ros.recording.sim_bags import bag_path, FORMATS, write_imu_bag
from accelcal_ros.recording.streams import read_imu
from accelcal_ros.sensor.recording import load_recording
from accelcal_ros.textformats import load_yaml_mapping
import numpy as np
import pytest

G = 9.80665
FIGURES = ('scale', 'bias', 'misalignment', 'scale_std', 'bias_std', 'residual_rms_g')


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    """Record a simulated calibration session (24 positions) as CSV and as bags."""
    root = tmp_path_factory.mktemp('calib')
    csv = root / 'rec.csv'
    assert main(['record', '-o', str(csv), '--duration', '100', '--rate', '50']) == 0
    t, accel = load_recording(str(csv))
    bags = {fmt: write_imu_bag(bag_path(root, 'rec', fmt), fmt, t, accel,
                               extra_topics=[('/velodyne_points', 'sensor_msgs/PointCloud2')])
            for fmt in FORMATS}
    yaml_csv = root / 'csv.yaml'
    assert main(['calibrate', str(csv), '-o', str(yaml_csv)]) == 0
    return {'csv': csv, 'bags': bags, 'yaml_csv': yaml_csv, 't': t, 'accel': accel}


@pytest.mark.parametrize('fmt', FORMATS)
def test_calibrate_from_bag_equals_csv(recording, fmt, tmp_path):
    """Every calibration figure from the bag equals the one from the CSV of the same data."""
    out = tmp_path / 'bag.yaml'
    assert main(['calibrate', str(recording['bags'][fmt]), '--topic', 'imu/data_raw',
                 '-o', str(out)]) == 0
    from_bag, from_csv = load_yaml_mapping(out), load_yaml_mapping(recording['yaml_csv'])
    for key in FIGURES:
        np.testing.assert_allclose(from_bag[key], from_csv[key], rtol=1e-9, atol=1e-12)
    assert from_bag['scale'][0] != 1.0  # the simulated sensor is not ideal


@pytest.mark.parametrize('fmt', ('mcap', 'ros1'))
def test_apply_writes_bag_with_calibrated_topic(recording, fmt, tmp_path, capsys):
    """Apply BAG -o BAG: the Imu topic calibrated (as apply to CSV), other topics copied."""
    src = recording['bags'][fmt]
    out = bag_path(tmp_path, 'out', fmt)
    csv_out = tmp_path / 'cal.csv'
    assert main(['apply', str(src), '--calibration', str(recording['yaml_csv']),
                 '-o', str(out)]) == 0
    assert main(['apply', str(recording['csv']), '--calibration', str(recording['yaml_csv']),
                 '-o', str(csv_out)]) == 0
    _, expected = load_recording(str(csv_out))
    with BagReader(out) as bag:
        topics = bag.topics()
        assert set(topics) == {'/imu/data_raw', '/velodyne_points'}
        imu = read_imu(bag, None)
    np.testing.assert_allclose(imu.accel, expected, atol=1e-6)
    still = np.abs(np.linalg.norm(imu.accel, axis=1) / G - 1.0)
    assert np.median(still) < 0.01  # calibrated magnitudes are ~1 g
    raw = np.linalg.norm(recording['accel'], axis=1) / G
    assert np.median(np.abs(raw - 1.0)) > 3 * np.median(still)
    # a second name keeps the raw topic beside the calibrated one
    both = bag_path(tmp_path, 'both', fmt)
    assert main(['apply', str(src), '--calibration', str(recording['yaml_csv']), '-o', str(both),
                 '--corrected-topic', '/imu/calibrated']) == 0
    with BagReader(both) as bag:
        assert {'/imu/data_raw', '/imu/calibrated'} <= set(bag.topics())
        np.testing.assert_allclose(read_imu(bag, '/imu/data_raw').accel, recording['accel'],
                                   atol=1e-9)
    # a name the bag already has: refused (it mixed both streams, 2x the messages, status 0)
    again = bag_path(tmp_path, 'again', fmt)
    assert main(['apply', str(both), '--topic', '/imu/data_raw', '--calibration',
                 str(recording['yaml_csv']), '-o', str(again),
                 '--corrected-topic', '/imu/calibrated']) == 1
    assert 'already has that topic' in capsys.readouterr().err and not again.exists()


@pytest.mark.parametrize('name, reason', [('bad topic!', 'only letters, digits'),
                                          ('', 'is empty'), ('/imu//cal', 'repeated /'),
                                          ('imu/', 'end with /'), ('/imu/9x', 'digit'),
                                          ('/' + 'a' * 247, 'more than 247')])
def test_apply_refuses_a_bad_corrected_topic_and_writes_nothing(recording, tmp_path, capsys,
                                                                name, reason):
    """--corrected-topic is a ROS topic name: a bad or empty one is one line, no bag."""
    out = tmp_path / 'out'
    assert main(['apply', str(recording['bags']['mcap']), '--calibration',
                 str(recording['yaml_csv']), '--corrected-topic', name, '-o', str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and '--corrected-topic' in err and reason in err
    assert not out.exists() and not list(tmp_path.iterdir())


def test_topic_name_rules_are_those_of_ros2():
    """topic_name_problem agrees with rclpy's validate_full_topic_name (when rclpy is here)."""
    from accelcal_ros.recording.bag import full_topic_name, topic_name_problem

    validate = pytest.importorskip('rclpy.validate_full_topic_name').validate_full_topic_name
    names = ['/imu', '/imu/data_raw', '/_x', '/a__b', '/A1/b2', '/', '//imu', '/imu/', '/1a',
             '/a/2', '/a b', '/a!', '/~/x', '/{node}', '/\u00e9', 'imu', '/a-b', '/a.b',
             '/' + 'a' * 246, '/' + 'a' * 247]
    for name in names:
        try:
            validate(name)
            valid = True
        except Exception:  # noqa: B902 - rclpy's InvalidTopicNameException
            valid = False
        assert (topic_name_problem(name) is None) == valid, name
    assert full_topic_name('imu/calibrated', '--corrected-topic') == '/imu/calibrated'


def test_apply_refuses_other_bag_family(recording, tmp_path, capsys):
    """A ROS 1 bag is written as ROS 1: a rosbag2 output is refused, nothing written."""
    out = tmp_path / 'out_dir'
    assert main(['apply', str(recording['bags']['ros1']), '--calibration',
                 str(recording['yaml_csv']), '-o', str(out)]) != 0
    assert 'ROS 1' in capsys.readouterr().err and not out.exists()


def test_attitude_from_bag_equals_csv(recording, tmp_path):
    """Attitude of a BAG prints the rows of attitude CSV (times from the first sample)."""
    a, b = tmp_path / 'a.csv', tmp_path / 'b.csv'
    assert main(['attitude', str(recording['csv']), '--calibration',
                 str(recording['yaml_csv']), '-o', str(a), '--every', '50']) == 0
    assert main(['attitude', str(recording['bags']['sqlite3']), '--calibration',
                 str(recording['yaml_csv']), '-o', str(b), '--every', '50']) == 0
    ra = np.loadtxt(a, delimiter=',', skiprows=1)
    rb = np.loadtxt(b, delimiter=',', skiprows=1)
    np.testing.assert_allclose(rb[:, 0], ra[:, 0], atol=1e-9)
    np.testing.assert_allclose(rb[:, 1:], ra[:, 1:], atol=1e-9)


def test_record_bag_replays_as_the_driver(tmp_path):
    """Record --bag: /imu/data_raw, Imu, sensor-data QoS, frame, covariances as the driver."""
    out = tmp_path / 'rec'
    assert main(['record', '--bag', str(out), '--duration', '100', '--rate', '50']) == 0
    meta = (out / 'metadata.yaml').read_text()
    assert 'storage_identifier: mcap' in meta and 'reliability: best_effort' in meta
    assert 'durability: volatile' in meta and 'depth: 5' in meta
    with BagReader(out) as bag:
        assert bag.listing() == '/imu/data_raw (sensor_msgs/Imu, 5000 messages)'
        msg = next(iter(bag.messages(['/imu/data_raw']))).msg
        assert msg.header.frame_id == 'imu_link'
        assert msg.orientation_covariance[0] == -1 and msg.angular_velocity_covariance[0] == -1
        assert msg.linear_acceleration_covariance[0] > 0
        assert read_imu(bag, None).gyro is None
    cal = tmp_path / 'c.yaml'
    assert main(['calibrate', str(out), '-o', str(cal)]) == 0
    assert load_yaml_mapping(cal)['residual_rms_g'] < 0.01
