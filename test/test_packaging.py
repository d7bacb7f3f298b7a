"""
package.xml declares only rosdep keys that rosdistro holds, so ``rosdep install`` resolves.

The verified keys, with the rosdistro files and commits they were read from, are in
``tools/rosdep-keys.txt``; a new dependency needs its key checked there first.
"""
import os
import re
import xml.etree.ElementTree as ElementTree

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_DEPEND_TAGS = ('depend', 'build_depend', 'build_export_depend', 'exec_depend',
                'test_depend', 'doc_depend')


def _declared_keys():
    root = ElementTree.parse(os.path.join(REPO, 'package.xml')).getroot()
    return [element.text.strip() for tag in _DEPEND_TAGS for element in root.iter(tag)]


def _verified_keys():
    keys = {}
    with open(os.path.join(REPO, 'tools', 'rosdep-keys.txt')) as handle:
        for line in handle:
            fields = line.split('#', 1)[0].split()
            if fields:
                keys[fields[0]] = fields[1]
    return keys


def test_every_declared_key_is_a_verified_rosdistro_key():
    """python3-smbus2 (no such key) and any other unverified key fail here."""
    declared = _declared_keys()
    assert declared and len(declared) == len(set(declared))
    verified = _verified_keys()
    assert set(declared) - set(verified) == set()
    assert set(verified.values()) <= {'jazzy/distribution.yaml', 'rosdep/python.yaml',
                                      'rosdistro-PR'}


def test_keys_added_after_the_snapshot_name_their_rosdistro_pull_request():
    """python3-smbus2 and python3-rosbags-pip: each with the merged PR that added it."""
    with open(os.path.join(REPO, 'tools', 'rosdep-keys.txt')) as handle:
        rows = [line.split() for line in handle if line.strip() and not line.startswith('#')]
    added = {row[0]: row[2] for row in rows if row[1] == 'rosdistro-PR'}
    assert {'python3-smbus2', 'python3-rosbags-pip'} <= set(added)
    assert all(re.fullmatch(r'#\d+', number) for number in added.values())
    assert 'python3-smbus2-pip' not in _declared_keys()


def test_no_unused_message_package_is_declared():
    """A ROS package is declared only if some module imports it."""
    sources = []
    for folder, _, files in os.walk(os.path.join(REPO, 'accelcal_ros')):
        sources += [os.path.join(folder, f) for f in files if f.endswith('.py')]
    imported = set()
    for path in sources:
        with open(path, encoding='utf-8') as handle:
            imported |= set(re.findall(r'^\s*(?:from|import) (\w+)', handle.read(), re.M))
    messages = {k for k in _declared_keys() if k.endswith(('_msgs', '_srvs', '_interfaces'))}
    assert messages - imported == set()
