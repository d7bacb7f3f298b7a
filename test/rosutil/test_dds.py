"""The image nodes' Fast DDS profile: taken from the install unless the user chose one."""
import os
import xml.etree.ElementTree as ElementTree

from accelcal_ros.rosutil import dds

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_the_shipped_profile_has_a_segment_for_camera_frames():
    """config/fastdds_large_shm.xml: an SHM transport of 128 MB, used by default."""
    tree = ElementTree.parse(os.path.join(REPO, 'config', dds.PROFILE_FILE))
    ns = {'p': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}
    sizes = [int(e.text) for e in tree.getroot().iterfind('.//p:segment_size', ns)]
    assert sizes == [128 * 2 ** 20]
    participant = tree.getroot().find('.//p:participant', ns)
    assert participant.get('is_default_profile') == 'true'


def test_the_profile_is_used_only_when_nothing_else_was_chosen(monkeypatch):
    """User's profile or another RMW: unchanged; otherwise the installed file."""
    for var in dds.PROFILE_VARIABLES + ('RMW_IMPLEMENTATION',):
        monkeypatch.delenv(var, raising=False)
    path = dds.use_large_message_profile()
    assert path is not None and os.path.isfile(path)
    assert os.environ['FASTRTPS_DEFAULT_PROFILES_FILE'] == path
    monkeypatch.setenv('FASTRTPS_DEFAULT_PROFILES_FILE', '/mine.xml')
    assert dds.use_large_message_profile() is None
    assert os.environ['FASTRTPS_DEFAULT_PROFILES_FILE'] == '/mine.xml'
    monkeypatch.delenv('FASTRTPS_DEFAULT_PROFILES_FILE')
    monkeypatch.setenv('RMW_IMPLEMENTATION', 'rmw_cyclonedds_cpp')
    assert dds.use_large_message_profile() is None
    assert 'FASTRTPS_DEFAULT_PROFILES_FILE' not in os.environ
