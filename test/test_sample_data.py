"""``accelcal sample-data``: refuses to replace anything; the journeys hold together."""
import os

from accelcal_ros.cli import main
from accelcal_ros.recording.bag import BagReader
from accelcal_ros.sample_data import journey_outputs, JOURNEYS


def test_refuses_existing_names_before_writing(tmp_path, capsys):
    """An existing rec.csv: one line naming it, nothing written, the file unchanged."""
    (tmp_path / 'rec.csv').write_text('mine\n')
    assert main(['sample-data', str(tmp_path), '--only', 'imu']) == 1
    err = capsys.readouterr().err
    assert 'already holds rec.csv' in err and err.count('\n') == 1
    assert (tmp_path / 'rec.csv').read_text() == 'mine\n'
    assert sorted(os.listdir(tmp_path)) == ['rec.csv']
    target = tmp_path / 'file'
    target.write_text('x')
    assert main(['sample-data', str(target)]) == 1
    assert 'is not a directory' in capsys.readouterr().err


def test_p2p_journey_bag_topics(tmp_path):
    """The P2P bag carries the topics the README's command names, 20 frames each."""
    assert main(['sample-data', str(tmp_path), '--only', 'p2p']) == 0
    assert sorted(os.listdir(tmp_path)) == journey_outputs('p2p')
    with BagReader(str(tmp_path / 'rosbag2_p2p')) as reader:
        counts = {name: t.count for name, t in reader.topics().items()}
    assert counts['/camera/image_raw'] == counts['/camera/camera_info'] == 20
    assert counts['/imu/data_raw'] == 100
    assert [name for name, _ in JOURNEYS] == ['imu', 'rig', 'drive', 'p2p', 'lidar', 'map']
