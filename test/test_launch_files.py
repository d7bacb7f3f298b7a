"""
Every launch file runs and follows the package's one convention (``launch`` is not installed).

Each ``launch/*.launch.py`` is imported with small stand-ins for ``launch``,
``launch_ros`` and ``ament_index_python`` that record what the file builds, and its
``generate_launch_description()`` is called. The convention checked: every launch file
takes ``driver`` (start imu_driver or not), ``backend`` and one ``<node>_params`` file per
node, defaulting to the installed ``config/<node>.yaml``; every node is an installed
executable named after it and loads its parameter file first; every parameter set in a
launch file is one the node declares; every launch argument is used; ``driver`` defaults
to true everywhere and the driver's exit stops the launch (``Shutdown`` with the reason);
every node executable has a launch file.
"""
import glob
import importlib.util
import os
import sys
import types

from accelcal_ros.node_params import NODE_PARAMS, node_specs
import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LAUNCH_FILES = sorted(glob.glob(os.path.join(REPO, 'launch', '*.launch.py')))


class _Recorded:
    """Any launch object: keeps its positional and keyword arguments."""

    def __init__(self, *args, **kwargs):
        self.args = args
        self.kwargs = kwargs

    def __eq__(self, other):
        return type(self) is type(other) and (self.args, self.kwargs) == \
            (other.args, other.kwargs)

    def __hash__(self):
        return hash((type(self).__name__, repr(self.args)))


class LaunchDescription(_Recorded):
    """Stand-in for launch.LaunchDescription."""


class DeclareLaunchArgument(_Recorded):
    """Stand-in for launch.actions.DeclareLaunchArgument."""


class LaunchConfiguration(_Recorded):
    """Stand-in for launch.substitutions.LaunchConfiguration."""


class IfCondition(_Recorded):
    """Stand-in for launch.conditions.IfCondition."""


class Node(_Recorded):
    """Stand-in for launch_ros.actions.Node."""


class Shutdown(_Recorded):
    """Stand-in for launch.actions.Shutdown."""


def _stub_modules(monkeypatch):
    def module(name, **attributes):
        mod = types.ModuleType(name)
        mod.__dict__.update(attributes)
        monkeypatch.setitem(sys.modules, name, mod)

    module('launch', LaunchDescription=LaunchDescription)
    module('launch.actions', DeclareLaunchArgument=DeclareLaunchArgument, Shutdown=Shutdown)
    module('launch.substitutions', LaunchConfiguration=LaunchConfiguration)
    module('launch.conditions', IfCondition=IfCondition)
    module('launch_ros')
    module('launch_ros.actions', Node=Node)
    module('ament_index_python')
    # the repository stands for the install's share/accelcal_ros (same config/ tree)
    module('ament_index_python.packages', get_package_share_directory=lambda name: REPO)


def _configurations(value):
    """Every LaunchConfiguration name inside a (nested) launch value."""
    if isinstance(value, LaunchConfiguration):
        yield value.args[0]
    elif isinstance(value, _Recorded):
        for item in list(value.args) + list(value.kwargs.values()):
            yield from _configurations(item)
    elif isinstance(value, (list, tuple)):
        for item in value:
            yield from _configurations(item)
    elif isinstance(value, dict):
        for item in value.values():
            yield from _configurations(item)


def _describe(path, monkeypatch):
    _stub_modules(monkeypatch)
    spec = importlib.util.spec_from_file_location('launch_under_test', path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    assert isinstance(description, LaunchDescription)
    actions = description.args[0]
    arguments = {a.args[0]: a.kwargs.get('default_value') for a in actions
                 if isinstance(a, DeclareLaunchArgument)}
    nodes = [a for a in actions if isinstance(a, Node)]
    return arguments, nodes


def test_there_are_launch_files():
    """The glob below must not silently test nothing."""
    assert len(LAUNCH_FILES) >= 6


def test_every_node_group_has_a_launch_file(monkeypatch):
    """Every node executable is started by at least one launch file."""
    started = set()
    for path in LAUNCH_FILES:
        started.update(n.kwargs['executable'] for n in _describe(path, monkeypatch)[1])
    assert started == set(NODE_PARAMS)


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=os.path.basename)
def test_launch_file_follows_the_convention(path, monkeypatch):
    """Driver backend and parameter files are taken the same way by every launch file."""
    arguments, nodes = _describe(path, monkeypatch)
    assert {'driver', 'backend', 'imu_driver_params'} <= set(arguments) or \
        os.path.basename(path) == 'driver.launch.py'
    assert arguments['backend'] == 'i2c'
    assert arguments.get('driver', 'true') == 'true'   # the same default everywhere
    executables = [n.kwargs['executable'] for n in nodes]
    assert 'imu_driver' in executables
    used = set()
    for node in nodes:
        exe = node.kwargs['executable']
        assert node.kwargs['package'] == 'accelcal_ros'
        assert exe in NODE_PARAMS and node.kwargs['name'] == exe
        params = node.kwargs['parameters']
        assert params[0] == LaunchConfiguration(f'{exe}_params'), exe
        default_file = arguments[f'{exe}_params']
        assert default_file == os.path.join(REPO, 'config', f'{exe}.yaml')
        assert os.path.isfile(default_file)
        declared = {s.name for s in node_specs(exe)}
        for overrides in params[1:]:
            assert set(overrides) <= declared, (exe, set(overrides) - declared)
        if exe == 'imu_driver':
            assert {'backend': LaunchConfiguration('backend')} in params[1:]
            # a driver that cannot start (no I2C bus) stops the launch, saying why
            (stop,) = node.kwargs['on_exit']
            assert isinstance(stop, Shutdown) and 'imu_driver exited' in stop.kwargs['reason']
            if os.path.basename(path) != 'driver.launch.py':
                assert node.kwargs['condition'] == IfCondition(LaunchConfiguration('driver'))
        used.update(_configurations(node))
    assert set(arguments) == used, f'declared but unused: {set(arguments) - used}'


def test_image_nodes_get_the_large_message_dds_profile(monkeypatch):
    """The stitcher and p2p nodes run with the shipped Fast DDS profile (dds_profile)."""
    for name in ('stitcher', 'p2p'):
        path = os.path.join(REPO, 'launch', f'{name}.launch.py')
        arguments, nodes = _describe(path, monkeypatch)
        assert os.path.isfile(arguments['dds_profile'])
        assert arguments['dds_profile'].endswith(os.path.join('config', 'fastdds_large_shm.xml'))
        (node,) = [n for n in nodes if n.kwargs['executable'] == name]
        env = node.kwargs['additional_env']
        assert list(_configurations(env)) == ['dds_profile']
        assert 'FASTRTPS_DEFAULT_PROFILES_FILE' in env
